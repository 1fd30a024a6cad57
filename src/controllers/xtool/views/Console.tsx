import { useState } from 'react';
import type { TabProps } from '../../../fleet/contract';
import { CommandButton, useStoreSelect } from '../../../fleet/react';
import { Button, EmptyState, Field, Panel, formatTime } from '../../../ui';
import { FULL_WIDTH, GRID } from './layout';
import type { XtoolSession } from '../session';

/** G-code console (supervisor): one line by GET /cmd, several by POST /cmd, with history. */
export function Console({ session }: TabProps<XtoolSession>) {
  const ctx = session.ctx;
  const history = useStoreSelect(session.detail, (s) => s.console);
  const [code, setCode] = useState('');
  const sent = [...new Set(history.map((h) => h.code))].slice(-8).reverse();
  return (
    <div className="ui-grid" style={GRID} data-testid="xtool-console">
      <Panel title="Send G-code">
        <Field
          label="G-code"
          hint="One line or many. Known: M28 home, M106 S0/1 laser cross, M17/M18 steppers on/off, G92 X Y set origin."
        >
          {(id) => (
            <textarea
              id={id}
              className="ui-input mono"
              style={FULL_WIDTH}
              value={code}
              onChange={(e) => setCode(e.target.value)}
              rows={4}
              spellCheck={false}
            />
          )}
        </Field>
        <div className="ui-row">
          {code.trim() ? (
            <CommandButton
              runner={ctx.commands}
              snapshot={ctx.snapshot}
              command={session.gcode}
              args={{ code }}
              variant="primary"
              onDone={() => setCode('')}
            >
              Send
            </CommandButton>
          ) : (
            <Button disabled>Send</Button>
          )}
        </div>
        {sent.length > 0 && (
          <div className="ui-row" style={{ marginTop: 10 }}>
            <span className="ui-muted">Again:</span>
            {sent.map((c) => (
              <Button key={c} onClick={() => setCode(c)} className="mono">
                {c.split('\n')[0]}
                {c.includes('\n') ? ' …' : ''}
              </Button>
            ))}
          </div>
        )}
      </Panel>
      <Panel title="History">
        {history.length === 0 ? (
          <EmptyState>Nothing sent yet.</EmptyState>
        ) : (
          <div className="ui-log" role="log">
            {history.map((h, i) => (
              <div key={i} className={h.ok ? undefined : 'lv-error'}>
                <span className="t">{formatTime(h.at)}</span>
                <span className="mono">{h.code.replace(/\n/g, ' | ')}</span> → {h.reply}
              </div>
            ))}
          </div>
        )}
      </Panel>
    </div>
  );
}
