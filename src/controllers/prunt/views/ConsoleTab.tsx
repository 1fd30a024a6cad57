import { useStore } from 'zustand';
import { useConsoleCommand } from '../../../fleet/console';
import type { TabProps } from '../../../fleet/contract';
import { type GcodeLine } from '../../../ui';
import { GcodeConsole } from '../../../ui/GcodeConsole';
import type { GcodeEntry, PruntSession } from '../session';

/** What a command looks like: Gcode_Command's state and ID, and the output the server sent. */
function line(e: GcodeEntry): GcodeLine {
  return {
    key: e.seq,
    at: e.at,
    sent: e.command,
    status: `${e.state}${e.id ? ` (ID ${e.id})` : ''}`,
    tone: e.state === 'Failed' || e.state === 'error' ? 'bad' : e.state === 'Completed' ? 'ok' : 'pending',
    reply: e.output,
  };
}

/** G-code console: `POST /run-command`, output from Gcode_Command where the server sends it. */
export function ConsoleTab({ session }: TabProps<PruntSession>) {
  const entries = useStore(session.store, (s) => s.gcode);
  const api = useStore(session.store, (s) => s.api);
  const sender = useConsoleCommand({
    runner: session.ctx.commands,
    snapshot: session.ctx.snapshot,
    command: session.cmd.runCommand,
    args: (text) => text,
  });
  return (
    <GcodeConsole
      testId="prunt-gcode"
      sender={sender}
      label="G-code command"
      placeholder="G28, M114, …"
      entries={entries.map(line)}
      notice={
        api === 'flat' && (
          <p className="ui-muted">This server (flat API) reports command errors in the log only.</p>
        )
      }
    />
  );
}
