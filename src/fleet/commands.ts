import { createStore, type StoreApi } from 'zustand/vanilla';
import { describeError, LinkError } from './errors';
import type { MachineLog } from './log';
import type { Hazard, MachineSnapshot, Role } from './types';
import { roleAtLeast } from './types';

/**
 * Commands are declared, not improvised (DESIGN.md principle 4). A command is never queued
 * while offline or while the link is in doubt (reconnecting, stale data: stops excepted), never
 * replayed after a reconnect, never sent twice while in flight; job and dangerous commands ask for
 * confirmation; every command is written to the audit log.
 *
 * Deadlines (issue 15). Every command has one (`deadlineMs`, default 5 s). Its requests carry it
 * to the gateway (`X-Shopdeck-Deadline`: the ms left; HttpClient adds it to any request sent with
 * the command's `commandId`), which aborts the upstream request at that moment — even while still
 * connecting — and answers 504 "not confirmed". The runner waits the same deadline (and a moment
 * for the gateway's answer): a command not confirmed by then is reported "not confirmed: it may or
 * may not have reached the machine — check the machine's state", never "failed", never retried;
 * its requests still under way are given up (the gateway drops them when not yet sent), nothing
 * more of it is sent, and the session reads the machine again. A command that transfers a file (a
 * request whose body is a file or a form, an upload with progress) is a long operation: no
 * overall deadline (the transfer's own timeout applies); each command request it sends besides
 * carries the whole deadline.
 */

/** A command's deadline unless it declares one (ms). */
export const DEFAULT_COMMAND_DEADLINE_MS = 5000;
/** The longest deadline a command may declare (the gateway caps the same way). */
export const MAX_COMMAND_DEADLINE_MS = 120_000;
/** The browser waits this much past the deadline for the gateway's own "not confirmed" answer. */
export const DEADLINE_GRACE_MS = 1000;
/** Data older than this puts the link in doubt: commands other than stops wait for fresh data. */
export const IN_DOUBT_AFTER_MS = 10_000;

export interface CommandContext {
  /** Send as `commandId` on the HTTP request so the gateway's audit log names it (and its deadline goes with it). */
  commandId: string;
  /** The command's deadline in ms (null: none). HttpClient sends what is left of it by itself. */
  deadlineMs?: number | null;
  /** Aborted when the console gives up on the command (not confirmed in time): pass it to work that is not a request. */
  signal?: AbortSignal;
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
  /**
   * On-demand reads a success makes stale (query keys under the machine), refetched at once; also
   * after a command that was not confirmed (it may have changed them).
   */
  invalidates?: readonly (readonly unknown[])[];
  /**
   * Not confirmed within this many ms, the command is reported "not confirmed" and the gateway
   * aborts it (default `DEFAULT_COMMAND_DEADLINE_MS`, at most `MAX_COMMAND_DEADLINE_MS`). A
   * command that legitimately takes long before the controller answers (a blocking G-code such
   * as homing) declares a longer one. `null`: no deadline (a long operation with its own
   * timeouts and progress; file transfers need not say so, they are recognized).
   */
  deadlineMs?: number | null;
  /**
   * A recovery meant for a link in doubt (the gateway reports the controller stuck, so its reads
   * fail): sent while reconnecting, as stops are. Never for a command that starts anything.
   */
  whileInDoubt?: true;
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

export type CommandOutcome = 'ok' | 'failed' | 'not-confirmed';

export interface CommandRecord {
  seq: number;
  at: number;
  machineId: string;
  commandId: string;
  label: string;
  user: string;
  ok: boolean;
  /** `not-confirmed`: it may or may not have reached the machine. */
  outcome: CommandOutcome;
  result: string;
}

export interface CommandState {
  inFlight: Record<string, true>;
  /** The last attempt of each command; `notConfirmed`: it may or may not have reached the machine. */
  last: Record<string, { ok: boolean; message: string; at: number; notConfirmed?: boolean }>;
}

export class CommandRefused extends Error {
  constructor(message: string) {
    super(message);
    this.name = 'CommandRefused';
  }
}

/** The words an operator reads for a command that was not confirmed. */
export const NOT_CONFIRMED_WORDS =
  "not confirmed: it may or may not have reached the machine — check the machine's state";

/**
 * A command that was not confirmed in time, or whose answer was lost: it may or may not have
 * reached the machine. Never a failure (it may have worked), never retried.
 */
export class CommandNotConfirmed extends Error {
  constructor(
    readonly label: string,
    /** What happened, for the log ("Printer 1 did not confirm pause within 5 s: …"). */
    readonly detail: string,
  ) {
    super(`${label}: ${NOT_CONFIRMED_WORDS}`);
    this.name = 'CommandNotConfirmed';
  }
}

/** The console stopped waiting for a command: its deadline (and the grace) passed. */
class DeadlinePassed extends Error {
  constructor(ms: number) {
    super(`no confirmation within ${Math.round(ms / 100) / 10} s`);
    this.name = 'DeadlinePassed';
  }
}

/**
 * A failure that leaves it open whether the command reached the machine: no whole answer came
 * (timeout, network, cut answer, given up), or the gateway said "not confirmed". The gateway's
 * other failures mean the command was not sent; a controller's answer (refusal, vendor error,
 * unreadable answer) is its answer.
 */
export function leavesItOpen(e: unknown): boolean {
  if (e instanceof CommandNotConfirmed || e instanceof DeadlinePassed) return true;
  if (e instanceof LinkError) {
    if (e.notConfirmed) return true;
    if (e.fromGateway) return false;
    // `aborted` is someone's own cancel (an upload the operator cancelled): that is its answer.
    return e.kind === 'timeout' || e.kind === 'network';
  }
  return false;
}

// ---------------------------------------------------------------- running commands

/**
 * A command being performed, as its requests see it: HttpClient looks it up by machine and
 * command id (what a family passes as `commandId`), sends what is left of its deadline, gives up
 * with it, and sends nothing once its deadline has passed.
 */
export interface CommandScope {
  readonly machineId: string;
  readonly commandId: string;
  /** Ms left until the deadline (≤ 0: passed); null: none now (no deadline, or a transfer runs). */
  remainingMs(): number | null;
  /** Aborted when the console gives up on the command. */
  readonly signal: AbortSignal;
  /** A request of the command carries a file: no deadline while it runs. Returns: it ended. */
  transfer(): () => void;
}

const scopes = new Map<string, RunningCommand>();
const scopeKey = (machineId: string, commandId: string): string => `${machineId}\u0000${commandId}`;

/** The running command `commandId` of `machineId`, if one is being performed now. */
export function commandScope(machineId: string, commandId: string): CommandScope | null {
  return scopes.get(scopeKey(machineId, commandId)) ?? null;
}

function deadlineOf(cmd: { deadlineMs?: number | null }): number | null {
  const d = cmd.deadlineMs;
  if (d === null) return null;
  if (d === undefined || !Number.isFinite(d) || d <= 0) return DEFAULT_COMMAND_DEADLINE_MS;
  return Math.min(Math.round(d), MAX_COMMAND_DEADLINE_MS);
}

class RunningCommand implements CommandScope {
  private readonly ctrl = new AbortController();
  private deadlineAt: number | null;
  private timer: ReturnType<typeof setTimeout> | null = null;
  private transfers = 0;
  /** It transferred a file: a long operation now (no overall deadline; each request has its own). */
  private long = false;
  private over = false;
  private giveUp: (e: Error) => void = () => undefined;
  /** Rejects when the deadline (and the grace for the gateway's answer) has passed. */
  readonly expired: Promise<never>;

  constructor(
    readonly machineId: string,
    readonly commandId: string,
    readonly deadlineMs: number | null,
    private readonly now: () => number,
  ) {
    this.deadlineAt = deadlineMs === null ? null : now() + deadlineMs;
    this.expired = new Promise<never>((_ok, fail) => {
      this.giveUp = fail;
    });
    this.expired.catch(() => undefined);
    this.arm();
  }

  get signal(): AbortSignal {
    return this.ctrl.signal;
  }

  private arm(): void {
    if (this.timer) clearTimeout(this.timer);
    this.timer = null;
    if (this.over || this.deadlineAt === null || this.transfers > 0 || this.long) return;
    const ms = Math.max(0, this.deadlineAt - this.now()) + DEADLINE_GRACE_MS;
    this.timer = setTimeout(() => {
      // Its requests still under way are given up first: nothing of it is sent from now on.
      this.ctrl.abort(new Error('not confirmed in time'));
      this.giveUp(new DeadlinePassed(this.deadlineMs ?? 0));
    }, ms);
  }

  remainingMs(): number | null {
    if (this.deadlineAt === null || this.transfers > 0) return null;
    // After a transfer (checks, a follow-up command): each request gets the whole deadline.
    if (this.long) return this.deadlineMs;
    return this.deadlineAt - this.now();
  }

  transfer(): () => void {
    this.transfers++;
    this.arm();
    let ended = false;
    return () => {
      if (ended) return;
      ended = true;
      this.transfers--;
      // A command that transferred a file is a long operation: what it reads afterwards (its
      // checks) has its own timeouts, and each command request it still sends its own deadline.
      this.long = true;
    };
  }

  /** The console is done with it: requests still under way are given up (`abandon`). */
  end(abandon: boolean): void {
    this.over = true;
    if (this.timer) clearTimeout(this.timer);
    this.timer = null;
    if (abandon) this.ctrl.abort(new Error('not confirmed in time'));
    const key = scopeKey(this.machineId, this.commandId);
    if (scopes.get(key) === this) scopes.delete(key);
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
  private readonly unconfirmedListeners = new Set<(cmd: CommandDecl<never>) => void>();

  constructor(
    private readonly machineId: string,
    private readonly snapshot: () => MachineSnapshot,
    private readonly log: MachineLog,
    private readonly principal: () => Principal,
    private readonly now: () => number = Date.now,
    /**
     * After a command that may have changed the machine: it succeeded, or it was not confirmed
     * (the query layer invalidates what it declared stale).
     */
    private readonly succeeded?: (cmd: CommandDecl<never>) => void,
  ) {}

  /**
   * Called when a command was not confirmed: the session reads the machine again at once (the
   * kernel does, for every family), so the operator sees what the machine actually does.
   */
  onUnconfirmed(listener: (cmd: CommandDecl<never>) => void): () => void {
    this.unconfirmedListeners.add(listener);
    return () => this.unconfirmedListeners.delete(listener);
  }

  /**
   * Why the link is in doubt for commands other than stops, or null: reconnecting, or online with
   * data older than `IN_DOUBT_AFTER_MS` (the machine may be doing something else than shown).
   */
  private doubt(snap: MachineSnapshot): string | null {
    if (snap.link === 'reconnecting')
      return 'The link to the machine is in doubt (reconnecting): commands are not queued; only stops are sent';
    if (snap.link !== 'online' || snap.updatedAt === null) return null;
    const age = this.now() - snap.updatedAt;
    if (age <= IN_DOUBT_AFTER_MS) return null;
    return `No fresh data from the machine for ${Math.floor(age / 1000)} s: its state is in doubt, so commands wait for fresh data (stops are still sent)`;
  }

  /**
   * Ms until the data goes stale and commands other than stops are blocked by time alone (null:
   * not online, no data time, or already stale): a button re-checks then.
   */
  msUntilInDoubt(): number | null {
    const snap = this.snapshot();
    if (snap.link !== 'online' || snap.updatedAt === null) return null;
    const left = snap.updatedAt + IN_DOUBT_AFTER_MS - this.now();
    return left >= 0 ? left : null;
  }

  /** Why this command cannot be sent now, or null. */
  blockedReason<A>(cmd: CommandDecl<A>): string | null {
    const who = this.principal();
    if (!roleAtLeast(who.role, cmd.role)) return `Needs the ${cmd.role} role (you are ${who.role})`;
    const snap = this.snapshot();
    // A stop is always worth one attempt (the socket may be down while HTTP still works); it is
    // sent once, now, and never queued or retried. Everything else waits for a live link whose
    // data is fresh: while the link is in doubt, what the operator sees may not be what is.
    const stop = cmd.hazard === 'stop' || cmd.whileInDoubt === true;
    if (!stop) {
      const doubt = this.doubt(snap);
      if (doubt) return doubt;
    }
    if (snap.link === 'connecting') return 'Connecting… (nothing is sent before the machine answers)';
    if (snap.link !== 'online' && !stop) return 'The machine is not connected: commands are not queued';
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
    const deadlineMs = deadlineOf(cmd);
    const running = new RunningCommand(this.machineId, cmd.id, deadlineMs, this.now);
    scopes.get(scopeKey(this.machineId, cmd.id))?.end(true);
    scopes.set(scopeKey(this.machineId, cmd.id), running);
    let outcome: CommandOutcome = 'failed';
    let message = '';
    try {
      const r = await Promise.race([
        cmd.perform(args, { commandId: cmd.id, deadlineMs, signal: running.signal }),
        running.expired,
      ]);
      outcome = 'ok';
      message = r || 'ok';
      this.log.info('command', `${cmd.label}: ${message}`);
      this.succeeded?.(cmd as CommandDecl<never>);
      return message;
    } catch (e) {
      if (leavesItOpen(e) || running.signal.aborted) {
        outcome = 'not-confirmed';
        const detail = e instanceof CommandNotConfirmed ? e.detail : describeError(e);
        const unconfirmed = new CommandNotConfirmed(cmd.label, detail);
        message = unconfirmed.message;
        this.log.warn('command', `${cmd.label}: ${NOT_CONFIRMED_WORDS} (${detail})`);
        throw unconfirmed;
      }
      message = describeError(e);
      this.log.error('command', `${cmd.label} failed: ${message}`);
      // The gateway could not send it at all: say so (it is safe to decide again).
      if (e instanceof LinkError && e.fromGateway && (e.status ?? 0) >= 500) {
        message = `${message} — not sent`;
        throw new LinkError(e.kind, message, { status: e.status, fromGateway: true });
      }
      throw e;
    } finally {
      running.end(outcome !== 'ok');
      const at = this.now();
      const ok = outcome === 'ok';
      const notConfirmed = outcome === 'not-confirmed';
      this.state.setState((s) => {
        const inFlight = { ...s.inFlight };
        delete inFlight[cmd.id];
        const last = notConfirmed ? { ok, message, at, notConfirmed } : { ok, message, at };
        return { inFlight, last: { ...s.last, [cmd.id]: last } };
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
            outcome,
            result: message,
          },
          ...s.records,
        ].slice(0, 500),
      }));
      if (notConfirmed) {
        // The machine may have changed: read it again now (what it declared stale, and its state).
        this.succeeded?.(cmd as CommandDecl<never>);
        for (const l of [...this.unconfirmedListeners]) {
          try {
            l(cmd as CommandDecl<never>);
          } catch {
            /* a listener must not change the outcome */
          }
        }
      }
    }
  }
}
