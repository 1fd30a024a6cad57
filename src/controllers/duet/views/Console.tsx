import { useState, type KeyboardEvent } from 'react';
import type { TabProps } from '../../../fleet/contract';
import { LogView, useCan, useSnapshot, useStoreSelect } from '../../../fleet/react';
import { Button, Notice, Panel } from '../../../ui';
import type { DuetSession } from '../session';
import { DuetFrame } from './common';

/**
 * The G-code console: `POST /machine/code` with history (↑/↓), replies, async mode, and the
 * controller's `messages` interleaved with timestamps and levels. The history is the machine's
 * log, so it survives reconnects.
 */
export function Console({ session }: TabProps<DuetSession>) {
  const ctx = session.ctx;
  const canSend = useCan(session.cmd.console.role);
  const history = useStoreSelect(session.store, (s) => s.codeHistory);
  const link = useSnapshot(ctx, (s) => s.link);
  const inFlight = useStoreSelect(ctx.commands.state, (s) => Boolean(s.inFlight[session.cmd.console.id]));
  const [code, setCode] = useState('');
  const [asyncMode, setAsyncMode] = useState(false);
  const [pos, setPos] = useState<number | null>(null);
  const [error, setError] = useState<string | null>(null);

  const send = async () => {
    const c = code.trim();
    if (!c) return;
    setError(null);
    try {
      await ctx.commands.run(session.cmd.console, { code: c, async: asyncMode });
      setCode('');
      setPos(null);
    } catch (e) {
      setError(e instanceof Error ? e.message : String(e));
    }
  };

  const onKey = (e: KeyboardEvent<HTMLInputElement>) => {
    if (e.key === 'Enter') {
      e.preventDefault();
      void send();
    } else if (e.key === 'ArrowUp' && history.length) {
      e.preventDefault();
      const p = pos === null ? history.length - 1 : Math.max(0, pos - 1);
      setPos(p);
      setCode(history[p] ?? '');
    } else if (e.key === 'ArrowDown' && pos !== null) {
      e.preventDefault();
      const p = pos + 1;
      if (p >= history.length) {
        setPos(null);
        setCode('');
      } else {
        setPos(p);
        setCode(history[p] ?? '');
      }
    }
  };

  return (
    <DuetFrame session={session}>
      <Panel title="Console" testId="duet-console">
        {!canSend && (
          <Notice tone="info">Sending G-code needs the supervisor role. You can read the console.</Notice>
        )}
        {canSend && (
          <div className="ui-row" style={{ marginBottom: 10 }}>
            <input
              className="ui-input mono"
              style={{ flex: 1, minWidth: 200, minHeight: 44 }}
              placeholder="G-code, e.g. M115"
              aria-label="G-code"
              value={code}
              onChange={(e) => setCode(e.target.value)}
              onKeyDown={onKey}
              list="duet-code-history"
              data-testid="duet-console-input"
              autoCapitalize="characters"
              autoComplete="off"
              spellCheck={false}
            />
            <datalist id="duet-code-history">
              {[...history].reverse().map((h) => (
                <option key={h} value={h} />
              ))}
            </datalist>
            <label className="ui-row" style={{ gap: 6, minHeight: 44 }}>
              <input
                type="checkbox"
                checked={asyncMode}
                onChange={(e) => setAsyncMode(e.target.checked)}
                style={{ width: 22, height: 22 }}
              />
              async
            </label>
            <Button
              variant="primary"
              onClick={() => void send()}
              disabled={!code.trim() || inFlight || link !== 'online'}
              busy={inFlight}
              data-testid="duet-console-send"
            >
              Send
            </Button>
          </div>
        )}
        {error && (
          <p role="alert" style={{ color: 'var(--bad)' }}>
            {error}
          </p>
        )}
        {history.length > 0 && canSend && (
          <div className="ui-row" style={{ marginBottom: 10 }}>
            {history
              .slice(-6)
              .reverse()
              .map((h) => (
                <Button key={h} className="mono" onClick={() => setCode(h)}>
                  {h}
                </Button>
              ))}
          </div>
        )}
        <LogView
          log={ctx.log}
          sources={['console', 'controller', 'link', 'command']}
          height={480}
          testId="duet-console-log"
        />
      </Panel>
    </DuetFrame>
  );
}
