import { useConsoleCommand } from '../../../fleet/console';
import { useStoreSelect } from '../../../fleet/react';
import { Panel, type GcodeLine } from '../../../ui';
import { GcodeConsole } from '../../../ui/GcodeConsole';
import type { ConsoleEntry, G2coreSession } from '../session';
import { Dro, StatBadge, WhyNot } from './common';

const STATE_WORDS: Record<ConsoleEntry['state'], string> = {
  sent: 'sent',
  running: 'running',
  done: 'ok',
  error: 'error',
  refused: 'refused',
};

/** What an MDI entry looks like: its state and operation, and the status text of an error. */
function line(e: ConsoleEntry): GcodeLine {
  return {
    key: e.seq,
    at: e.at,
    sent: e.lines.join('\n'),
    status: `${STATE_WORDS[e.state]}${e.opId ? ` (operation ${e.opId})` : ''}`,
    tone: e.state === 'done' ? 'ok' : e.state === 'error' || e.state === 'refused' ? 'bad' : 'pending',
    reply: e.message ? [e.message] : [],
  };
}

/** MDI: lines run as one operation; replies and the status text of errors. */
export function ConsoleTab({ session }: { session: G2coreSession }) {
  const entries = useStoreSelect(session.detail, (d) => d.console);
  const sender = useConsoleCommand({
    runner: session.ctx.commands,
    snapshot: session.ctx.snapshot,
    command: session.mdi,
    args: (text) => ({ text }),
  });
  return (
    <div style={{ display: 'grid', gap: 14 }}>
      <GcodeConsole
        title="G-code console (MDI)"
        actions={<StatBadge session={session} />}
        testId="g2-console"
        sender={sender}
        label="G-code or JSON lines (one per line)"
        placeholder={'G21 G90\nG0 X10 Y10'}
        multiline
        entries={entries.map(line)}
        emptyText="Nothing sent yet. Lines run as one operation."
        footer={<WhyNot session={session} command={session.mdi} />}
      />
      <Panel title="Position">
        <Dro session={session} compact />
      </Panel>
    </div>
  );
}
