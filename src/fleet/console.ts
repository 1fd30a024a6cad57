import { useStore, type StoreApi } from 'zustand';
import type { GcodeSender } from '../ui/GcodeConsole';
import { useBlockedReason } from './kernel/commands';
import { confirmationText, type CommandDecl, type CommandRunner } from './commands';
import { useRole } from './react';
import type { MachineSnapshot } from './types';
import { roleAtLeast } from './types';

/**
 * Wires `GcodeConsole` (src/ui) to a family's console command: the role that may send it, its
 * in-flight state, why it is blocked, its confirmation, and `runner.run` (refusal and the audit
 * log), exactly like `CommandButton`.
 */
export function useConsoleCommand<A>(opts: {
  runner: CommandRunner;
  snapshot: StoreApi<MachineSnapshot>;
  command: CommandDecl<A>;
  /** How a typed text becomes the command's arguments. */
  args: (text: string) => A;
  /** Lines that need a confirmation here, besides what the command itself declares. */
  confirm?: (text: string) => string | null;
}): GcodeSender {
  const { runner, command, args } = opts;
  const role = useRole();
  const busy = useStore(runner.state, (s) => Boolean(s.inFlight[command.id]));
  // Follows every store the command's availability reads (the snapshot and the family's own).
  const blocked = useBlockedReason(runner, opts.snapshot, command);
  return {
    canSend: roleAtLeast(role, command.role),
    role: command.role,
    busy,
    // In flight is shown as busy, not as a reason.
    blockedReason: () => (busy ? null : blocked),
    confirm: (text) => confirmationText(command, args(text)) ?? opts.confirm?.(text) ?? null,
    send: (text) => runner.run(command, args(text)),
  };
}
