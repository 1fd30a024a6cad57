import { createStore, type StoreApi } from 'zustand/vanilla';
import { describeError } from './errors';
import type { MachineLog } from './log';
import type { Hazard, MachineSnapshot, Role } from './types';
import { roleAtLeast } from './types';

/**
 * Commands are declared, not improvised (DESIGN.md principle 4). A command is never queued
 * while offline, never replayed after a reconnect, never sent twice while in flight; job and
 * dangerous commands ask for confirmation; every command is written to the audit log.
 */

export interface CommandContext {
  /** Send as `commandId` on the HTTP request so the gateway's audit log names it. */
  commandId: string;
}

export interface CommandDecl<A = void> {
  /** "xtool.pause" — family-prefixed, stable: it appears in the audit log. */
  id: string;
  label: string;
  hazard: Hazard;
  /** Least role that may use it; must match the family's access declaration. */
  role: Role;
  /**
   * Confirmation text. Undefined: confirm `job` (when it starts or resumes motion) and
   * `dangerous` with a generic text. `false`: never confirm (pause, emergency stop).
   */
  confirm?: string | false | ((args: A) => string);
  /** Ask twice (firmware upgrades). */
  confirmTwice?: boolean;
  /** True when the command makes sense in this state, else the reason it does not. */
  available?: (snap: MachineSnapshot) => true | string;
  /**
   * The stores `available` reads besides the machine snapshot: a button subscribes to exactly
   * these, so what it shows is what the runner would do. Set by `defineCommands`.
   */
  needs?: readonly Subscribable[];
  /** On-demand reads a success makes stale (query keys under the machine), refetched at once. */
  invalidates?: readonly (readonly unknown[])[];
  /** Does the work. Resolves with a short result for the log ("ok", "job paused"). */
  perform: (args: A, ctx: CommandContext) => Promise<string | void>;
}

/** Anything a component can subscribe to (a zustand store). */
export interface Subscribable {
  subscribe(listener: () => void): () => void;
}

/** A command of any argument type, as kept in a session's list (`perform` takes what it takes). */
export type AnyCommand = CommandDecl<never>;

export function confirmationText<A>(cmd: CommandDecl<A>, args: A): string | null {
  if (cmd.confirm === false) return null;
  if (typeof cmd.confirm === 'function') return cmd.confirm(args);
  if (typeof cmd.confirm === 'string') return cmd.confirm;
  if (cmd.hazard === 'dangerous') return `${cmd.label}: this is a dangerous command. Send it?`;
  if (cmd.hazard === 'job') return `${cmd.label}?`;
  return null;
}

export interface CommandRecord {
  seq: number;
  at: number;
  machineId: string;
  commandId: string;
  label: string;
  user: string;
  ok: boolean;
  result: string;
}

export interface CommandState {
  inFlight: Record<string, true>;
  last: Record<string, { ok: boolean; message: string; at: number }>;
}

export class CommandRefused extends Error {
  constructor(message: string) {
    super(message);
    this.name = 'CommandRefused';
  }
}

/** The console's own record of commands sent from this browser (the gateway keeps the real audit log). */
export const commandHistory: StoreApi<{ records: CommandRecord[] }> = createStore(() => ({
  records: [] as CommandRecord[],
}));
let historySeq = 0;

export interface Principal {
  name: string;
  role: Role;
}

export class CommandRunner {
  readonly state: StoreApi<CommandState> = createStore<CommandState>(() => ({ inFlight: {}, last: {} }));

  constructor(
    private readonly machineId: string,
    private readonly snapshot: () => MachineSnapshot,
    private readonly log: MachineLog,
    private readonly principal: () => Principal,
    private readonly now: () => number = Date.now,
    /** After a command succeeded (the query layer invalidates what it declared stale). */
    private readonly succeeded?: (cmd: CommandDecl<never>) => void,
  ) {}

  /** Why this command cannot be sent now, or null. */
  blockedReason<A>(cmd: CommandDecl<A>): string | null {
    const who = this.principal();
    if (!roleAtLeast(who.role, cmd.role)) return `Needs the ${cmd.role} role (you are ${who.role})`;
    const snap = this.snapshot();
    // A stop is always worth one attempt (the socket may be down while HTTP still works); it is
    // sent once, now, and never queued or retried. Everything else waits for a live link.
    if (snap.link !== 'online' && !(cmd.hazard === 'stop' && snap.link !== 'connecting'))
      return 'The machine is not connected: commands are not queued';
    if (this.state.getState().inFlight[cmd.id]) return 'Already being sent';
    const avail = cmd.available?.(snap) ?? true;
    return avail === true ? null : avail;
  }

  /**
   * Send a command once. Confirmation is the caller's job (the UI asks before calling);
   * this refuses anything not allowed right now and records every attempt.
   */
  async run<A>(cmd: CommandDecl<A>, args: A): Promise<string> {
    const blocked = this.blockedReason(cmd);
    if (blocked) {
      this.log.warn('command', `${cmd.label}: not sent — ${blocked}`);
      throw new CommandRefused(blocked);
    }
    this.state.setState((s) => ({ inFlight: { ...s.inFlight, [cmd.id]: true } }));
    this.log.info('command', `${cmd.label}: sending`);
    let ok = false;
    let message = '';
    try {
      const r = await cmd.perform(args, { commandId: cmd.id });
      ok = true;
      message = r || 'ok';
      this.log.info('command', `${cmd.label}: ${message}`);
      this.succeeded?.(cmd as CommandDecl<never>);
      return message;
    } catch (e) {
      message = describeError(e);
      this.log.error('command', `${cmd.label} failed: ${message}`);
      throw e;
    } finally {
      const at = this.now();
      this.state.setState((s) => {
        const inFlight = { ...s.inFlight };
        delete inFlight[cmd.id];
        return { inFlight, last: { ...s.last, [cmd.id]: { ok, message, at } } };
      });
      commandHistory.setState((s) => ({
        records: [
          {
            seq: ++historySeq,
            at,
            machineId: this.machineId,
            commandId: cmd.id,
            label: cmd.label,
            user: this.principal().name,
            ok,
            result: message,
          },
          ...s.records,
        ].slice(0, 500),
      }));
    }
  }
}
