import { useState } from 'react';
import { useStore } from 'zustand';
import type { TabProps } from '../../../fleet/contract';
import { CommandButton } from '../../../fleet/react';
import { Button, formatTime, Panel } from '../../../ui';
import type { PruntSession } from '../session';
import './prunt.css';

/** G-code console: `POST /run-command`, history (↑/↓), output from Gcode_Command where the server sends it. */
export function ConsoleTab({ session }: TabProps<PruntSession>) {
  const [text, setText] = useState('');
  const [pos, setPos] = useState<number | null>(null);
  const [error, setError] = useState<string | null>(null);
  const entries = useStore(session.store, (s) => s.gcode);
  const api = useStore(session.store, (s) => s.api);
  const history = entries.map((e) => e.command);
  const run = session.ctx.commands;
  return (
    <Panel title="G-code console" testId="prunt-console">
      <form
        className="pr-console"
        onSubmit={(e) => {
          // Enter sends, through the command runner like the button (never queued, audited).
          e.preventDefault();
          const cmd = text.trim();
          if (!cmd) return;
          setError(null);
          run.run(session.cmd.runCommand, cmd).then(
            () => setText(''),
            (err: unknown) => setError(err instanceof Error ? err.message : String(err)),
          );
        }}
      >
        <input
          className="ui-input"
          value={text}
          placeholder="G28, M114, …"
          aria-label="G-code command"
          autoCapitalize="characters"
          onChange={(e) => {
            setText(e.target.value);
            setPos(null);
          }}
          onKeyDown={(e) => {
            if (e.key === 'ArrowUp' && history.length) {
              const p = pos === null ? history.length - 1 : Math.max(0, pos - 1);
              setPos(p);
              setText(history[p] ?? '');
              e.preventDefault();
            } else if (e.key === 'ArrowDown' && pos !== null) {
              const p = pos + 1;
              setPos(p >= history.length ? null : p);
              setText(p >= history.length ? '' : (history[p] ?? ''));
              e.preventDefault();
            }
          }}
          data-testid="prunt-gcode-input"
        />
        {text.trim() ? (
          <CommandButton
            runner={run}
            snapshot={session.ctx.snapshot}
            command={session.cmd.runCommand}
            args={text.trim()}
            variant="primary"
            onDone={() => setText('')}
          >
            Send
          </CommandButton>
        ) : (
          <Button variant="primary" disabled title="Type a command first">
            Send
          </Button>
        )}
      </form>
      {error && (
        <p role="alert" className="pr-error" data-testid="prunt-gcode-error">
          {error}
        </p>
      )}
      {api === 'flat' && (
        <p className="ui-muted">This server (flat API) reports command errors in the log only.</p>
      )}
      <div className="pr-gcode" role="log" aria-live="polite" data-testid="prunt-gcode-history">
        {entries.length === 0 && <p className="ui-muted">No commands sent from this page yet.</p>}
        {[...entries].reverse().map((e) => (
          <div key={e.seq} className={e.state === 'Failed' || e.state === 'error' ? 'failed' : ''}>
            <span className="ui-muted">{formatTime(e.at)}</span> <strong>{e.command}</strong> — {e.state}
            {e.id ? ` (ID ${e.id})` : ''}
            {e.output.map((o, i) => (
              <div key={i}>{o}</div>
            ))}
          </div>
        ))}
      </div>
    </Panel>
  );
}
