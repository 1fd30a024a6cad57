import type { AnyCommand } from '../commands';
import { LinkTracker, type MachineSession, type SessionContext } from '../contract';
import { LinkError } from '../errors';
import { Poller, SocketLink, type SocketLinkOptions } from '../link';
import type { MachineInfo } from '../types';
import { Lifecycle, type RunToken } from './lifecycle';

/**
 * The session kernel every family builds on. A family session declares what it polls
 * (`poll`), what it streams (`stream`) and what it commands (`defineCommands`); the kernel
 * owns when those run:
 *
 * - one lifecycle: `start()`/`stop()` idempotent, an AbortController per run (requests made
 *   with `this.signal` are cancelled on stop), a timer registry cleared on stop;
 * - nothing written after stop: a poll's answer is applied only if the run that asked is still
 *   the current run (a stop, or a stop and a new start, in between drops it);
 * - polls never overlap, slow down while the page is hidden, and `kick()` after a command polls
 *   once more right after any poll in flight;
 * - streams reconnect with backoff, under a declared heartbeat policy, with optional fallback
 *   polling; they are closed on stop;
 * - on-demand reads go through `ctx.queries` and are cancelled and dropped on stop;
 * - a command that was not confirmed (commands.ts: deadline passed, answer lost) makes every poll
 *   run again at once, so the operator sees what the machine actually does before deciding again.
 */
export interface PollSpec<T> {
  /** For the log: "status", "jobs". */
  name: string;
  /** The read. Pass `signal` to the request so a stop cancels it. */
  read: (signal: AbortSignal) => Promise<T>;
  /** Writes the answer; called only while the run that read it is current. */
  apply: (data: T) => void;
  /** Interval from the end of one poll to the start of the next. */
  intervalMs: () => number;
  /** A failed read (not called after stop): return the delay before the next try. */
  failed?: (e: unknown) => number | void;
  /** Wait for `kick()` or this many ms before the first poll (default 0). */
  firstDelayMs?: number;
  /** Only poll while this says yes (checked before each poll). */
  when?: () => boolean;
}

export abstract class KernelSession implements MachineSession {
  readonly machine: MachineInfo;
  readonly life = new Lifecycle();
  readonly tracker: LinkTracker;
  abstract readonly commands: Readonly<Record<string, AnyCommand>>;
  private readonly pollers: Array<{ poller: Poller; firstDelayMs: number }> = [];
  private readonly streams: Array<{ make: () => SocketLink; link: SocketLink | null }> = [];

  constructor(readonly ctx: SessionContext) {
    this.machine = ctx.machine;
    this.tracker = new LinkTracker(ctx);
  }

  /** The current run's signal, for requests made by the session. */
  get signal(): AbortSignal {
    return this.life.signal;
  }

  get started(): boolean {
    return this.life.running;
  }

  start(): void {
    if (!this.life.start()) return;
    this.life.onStop(this.ctx.commands.onUnconfirmed(() => this.pollNow()));
    this.onStart();
    for (const p of this.pollers) p.poller.start(p.firstDelayMs);
    for (const s of this.streams) s.link = s.make();
  }

  stop(): void {
    if (!this.life.running) return;
    for (const p of this.pollers) p.poller.stop();
    for (const s of this.streams) {
      s.link?.close();
      s.link = null;
    }
    this.onStop();
    this.life.stop();
    this.ctx.queries.clear();
  }

  /**
   * Read the machine again now: every poll runs at once (or right after the one in flight). Called
   * after a command that was not confirmed; a family may call it too.
   */
  pollNow(): void {
    if (!this.life.running) return;
    for (const p of this.pollers) p.poller.kick();
  }

  /** Family start work beyond polls and streams (an identity read). Runs before them. */
  protected onStart(): void {}

  /** Family stop work (say goodbye to the controller). Runs before the lifecycle ends. */
  protected onStop(): void {}

  /** Declares a poll; started and stopped with the session. */
  protected poll<T>(spec: PollSpec<T>): Poller {
    let retryMs: number | undefined;
    const poller = new Poller({
      run: async () => {
        if (spec.when && !spec.when()) return;
        const run = this.life.current();
        let data: T;
        try {
          data = await spec.read(run.signal);
        } catch (e) {
          if (!run.alive()) return;
          throw e;
        }
        if (run.alive()) spec.apply(data);
      },
      intervalMs: spec.intervalMs,
      visibility: this.ctx.visibility,
      onError: (e) => {
        if (!this.life.running) return;
        const d = spec.failed ? spec.failed(e) : this.tracker.fail(e);
        retryMs = typeof d === 'number' ? d : undefined;
      },
      retryDelayMs: () => retryMs ?? spec.intervalMs(),
      // Shown only on a tile: on the page's shared grid, so the fleet's answers come together.
      aligned: () => !this.ctx.detail(),
      now: this.ctx.now,
      scheduler: this.life.scheduler,
    });
    this.pollers.push({ poller, firstDelayMs: spec.firstDelayMs ?? 0 });
    return poller;
  }

  /**
   * Declares a stream; the socket is created on start and closed on stop. Handlers are bound
   * to the run: a message or close that arrives after stop is dropped.
   */
  protected stream(options: () => SocketLinkOptions): { current: () => SocketLink | null } {
    const entry: { make: () => SocketLink; link: SocketLink | null } = {
      link: null,
      make: () => {
        const o = options();
        const run = this.life.current();
        return new SocketLink({
          scheduler: this.life.scheduler,
          ...o,
          onOpen: o.onOpen && (() => run.alive() && o.onOpen?.()),
          onMessage: (d) => {
            if (run.alive()) o.onMessage(d);
          },
          onClose: (code, reason) => (run.alive() ? o.onClose?.(code, reason) : false),
          heartbeat: o.heartbeat && {
            ...o.heartbeat,
            onDead: (why) => {
              if (run.alive()) o.heartbeat?.onDead?.(why);
            },
          },
        });
      },
    };
    this.streams.push(entry);
    return { current: () => entry.link };
  }

  /** The run a piece of async work belongs to: check `alive()` before writing its result. */
  protected run(): RunToken {
    return this.life.current();
  }

  /** A timeout of the current run (cleared on stop). */
  protected later(fn: () => void, ms: number): void {
    this.life.setTimeout(fn, ms);
  }

  /** A link failure in the words of LinkTracker (for streams' `onClose`). */
  protected linkLost(message: string, kind: 'network' | 'timeout' = 'network'): number {
    return this.tracker.fail(new LinkError(kind, message));
  }
}
