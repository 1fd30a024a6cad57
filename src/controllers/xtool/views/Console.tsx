import { useConsoleCommand } from '../../../fleet/console';
import type { TabProps } from '../../../fleet/contract';
import { useStoreSelect } from '../../../fleet/react';
import { type GcodeLine } from '../../../ui';
import { GcodeConsole } from '../../../ui/GcodeConsole';
import type { ConsoleEntry, XtoolSession } from '../session';

/** What a line looks like: the laser's one reply (or the error), nothing else comes back. */
function line(e: ConsoleEntry, i: number): GcodeLine {
  return { key: i, at: e.at, sent: e.code, tone: e.ok ? 'ok' : 'bad', reply: [e.reply] };
}

/** G-code console (supervisor): one line by GET /cmd, several by POST /cmd. */
export function Console({ session }: TabProps<XtoolSession>) {
  const ctx = session.ctx;
  const entries = useStoreSelect(session.detail, (s) => s.console);
  const sender = useConsoleCommand({
    runner: ctx.commands,
    snapshot: ctx.snapshot,
    command: session.gcode,
    args: (code) => ({ code }),
  });
  return (
    <GcodeConsole
      title="Send G-code"
      testId="xtool-console"
      sender={sender}
      label="G-code (one line or many)"
      placeholder={'M28\nM106 S1'}
      multiline
      entries={entries.map(line)}
      notice={
        <p className="ui-muted">
          Known: M28 home, M106 S0/1 laser cross, M17/M18 steppers on/off, G92 X Y set origin.
        </p>
      }
    />
  );
}
