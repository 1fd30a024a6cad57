import { useState } from 'react';
import { useConsoleCommand } from '../../../fleet/console';
import type { TabProps } from '../../../fleet/contract';
import { LogView, useStoreSelect } from '../../../fleet/react';
import { GcodeConsole } from '../../../ui/GcodeConsole';
import type { DuetSession } from '../session';
import { DuetFrame } from './common';

/**
 * The G-code console: `POST /machine/code` (optionally async). Replies and the controller's
 * `messages` are the machine log, so the history survives reconnects; ↑/↓ recall the codes typed.
 */
export function Console({ session }: TabProps<DuetSession>) {
  const ctx = session.ctx;
  const [asyncMode, setAsyncMode] = useState(false);
  const recall = useStoreSelect(session.store, (s) => s.codeHistory);
  const sender = useConsoleCommand({
    runner: ctx.commands,
    snapshot: ctx.snapshot,
    command: session.cmd.console,
    args: (code) => ({ code, async: asyncMode }),
  });
  return (
    <DuetFrame session={session}>
      <GcodeConsole
        title="Console"
        testId="duet-console"
        sender={sender}
        placeholder="G-code, e.g. M115"
        recall={recall}
        options={
          <label className="ui-row" style={{ gap: 6, minHeight: 44 }}>
            <input
              type="checkbox"
              checked={asyncMode}
              onChange={(e) => setAsyncMode(e.target.checked)}
              style={{ width: 22, height: 22 }}
            />
            async
          </label>
        }
        log={
          <LogView
            log={ctx.log}
            sources={['console', 'controller', 'link', 'command']}
            height={480}
            testId="duet-console-log"
          />
        }
      />
    </DuetFrame>
  );
}
