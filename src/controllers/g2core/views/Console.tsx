import { useState } from 'react';
import { CommandButton, useStoreSelect } from '../../../fleet/react';
import { Button, Panel, formatTime } from '../../../ui';
import type { ConsoleEntry, G2coreSession } from '../session';
import { Dro, StatBadge, WhyNot } from './common';

const STATE_WORDS: Record<ConsoleEntry['state'], string> = {
  sent: 'sent',
  running: 'running',
  done: 'ok',
  error: 'error',
  refused: 'refused',
};

/** MDI: lines run as one operation; replies and the status text of errors. */
export function ConsoleTab({ session }: { session: G2coreSession }) {
  const entries = useStoreSelect(session.detail, (d) => d.console);
  const [text, setText] = useState('');
  const { commands: runner, snapshot } = session.ctx;
  return (
    <div style={{ display: 'grid', gap: 14 }}>
      <Panel title="G-code console (MDI)" actions={<StatBadge session={session} />} testId="g2-console">
        <div className="g2-console" role="log" aria-live="polite" data-testid="g2-console-log">
          {entries.length === 0 && (
            <div className="ui-muted">Nothing sent yet. Lines run as one operation.</div>
          )}
          {entries.map((e) => (
            <div className="entry" key={e.seq} data-testid={`g2-console-${e.seq}`}>
              <div className="lines">
                <span className="ui-muted">{formatTime(e.at)} &gt; </span>
                {e.lines.join('\n')}
              </div>
              <div
                className={`reply ${e.state === 'done' ? 'ok' : e.state === 'error' || e.state === 'refused' ? 'bad' : ''}`}
              >
                {STATE_WORDS[e.state]}
                {e.opId ? ` (operation ${e.opId})` : ''}
                {e.message ? `: ${e.message}` : ''}
              </div>
            </div>
          ))}
        </div>
        <form onSubmit={(ev) => ev.preventDefault()} style={{ marginTop: 10, display: 'grid', gap: 8 }}>
          <label htmlFor="g2-mdi" className="ui-muted">
            G-code or JSON lines (one per line)
          </label>
          <textarea
            id="g2-mdi"
            className="g2-textarea"
            style={{ minHeight: 80 }}
            value={text}
            onChange={(e) => setText(e.target.value)}
            placeholder={'G21 G90\nG0 X10 Y10'}
            data-testid="g2-mdi-input"
          />
          <div className="ui-row">
            {text.trim() === '' ? (
              <Button disabled variant="primary" title="Type a line first">
                Send
              </Button>
            ) : (
              <CommandButton
                runner={runner}
                snapshot={snapshot}
                command={session.mdi}
                args={{ text }}
                variant="primary"
                onDone={() => setText('')}
                testId="g2-mdi-send"
              >
                Send
              </CommandButton>
            )}
          </div>
          <WhyNot session={session} command={session.mdi} />
        </form>
      </Panel>
      <Panel title="Position">
        <Dro session={session} compact />
      </Panel>
    </div>
  );
}
