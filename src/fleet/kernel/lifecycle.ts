import { Deadline, pageScheduler, type Cancel, type DeadlineSpec, type Scheduler } from './scheduler';

/**
 * A session's lifecycle: one run between `start()` and `stop()`. Each run has its own
 * AbortController (requests pass `signal` and are cancelled on stop) and its own timer registry
 * (every timer set through it is cleared on stop; the timers are the scheduler's). Work that
 * outlives its run cannot write: `guard(fn)` and `current()` tie a callback to the run that made
 * it, so an answer arriving after stop (or after stop and a new start) is dropped.
 */

/** A timer of a run (clear it with the run's `clearTimeout`/`clearInterval`). */
export type Handle = { readonly cancel: Cancel };

/** The run a callback belongs to: `alive()` is false once that run stopped. */
export interface RunToken {
  readonly signal: AbortSignal;
  alive(): boolean;
}

const STOPPED: RunToken = {
  signal: AbortSignal.abort(new Error('stopped')),
  alive: () => false,
};

export class Lifecycle {
  private ctrl: AbortController | null = null;
  private generation = 0;
  private readonly timeouts = new Set<Handle>();
  private readonly intervals = new Set<Handle>();
  private cleanups: Array<() => void> = [];

  constructor(readonly scheduler: Scheduler = pageScheduler) {}

  /** True between start() and stop(). */
  get running(): boolean {
    return this.ctrl !== null;
  }

  /** The current run's signal (already aborted when stopped). */
  get signal(): AbortSignal {
    return this.ctrl?.signal ?? STOPPED.signal;
  }

  /** Starts a run; false when one is running already (start is idempotent). */
  start(): boolean {
    if (this.ctrl) return false;
    this.ctrl = new AbortController();
    this.generation++;
    return true;
  }

  /** Ends the run: aborts its requests, clears its timers, runs its `onStop` cleanups (newest first). */
  stop(): void {
    const ctrl = this.ctrl;
    if (!ctrl) return;
    this.ctrl = null;
    this.generation++;
    for (const t of this.timeouts) t.cancel();
    for (const t of this.intervals) t.cancel();
    this.timeouts.clear();
    this.intervals.clear();
    const cleanups = this.cleanups.reverse();
    this.cleanups = [];
    for (const fn of cleanups) {
      try {
        fn();
      } catch {
        /* a cleanup must not keep the others from running */
      }
    }
    ctrl.abort(new Error('stopped'));
  }

  /** The current run, to check later whether it is still the current run. */
  current(): RunToken {
    const ctrl = this.ctrl;
    if (!ctrl) return STOPPED;
    const gen = this.generation;
    return { signal: ctrl.signal, alive: () => this.generation === gen && this.ctrl === ctrl };
  }

  /** Wraps `fn` so it runs only while the run that wrapped it is still current. */
  guard<T extends unknown[]>(fn: (...args: T) => void): (...args: T) => void {
    const run = this.current();
    return (...args: T) => {
      if (run.alive()) fn(...args);
    };
  }

  /** A timeout of this run: not set when stopped, cleared on stop, never fires after stop. */
  setTimeout(fn: () => void, ms: number): Handle | null {
    if (!this.ctrl) return null;
    const guarded = this.guard(fn);
    const t: Handle = {
      cancel: this.scheduler.after(ms, () => {
        this.timeouts.delete(t);
        guarded();
      }),
    };
    this.timeouts.add(t);
    return t;
  }

  clearTimeout(t: Handle | null): void {
    if (t === null) return;
    t.cancel();
    this.timeouts.delete(t);
  }

  /** An interval of this run, cleared on stop: the scheduler's shared tick of that period. */
  setInterval(fn: () => void, ms: number): Handle | null {
    if (!this.ctrl) return null;
    const t: Handle = { cancel: this.scheduler.every(ms, this.guard(fn)) };
    this.intervals.add(t);
    return t;
  }

  clearInterval(t: Handle | null): void {
    if (t === null) return;
    t.cancel();
    this.intervals.delete(t);
  }

  /**
   * A deadline of this run (see `Deadline`): its timer is one of this run's (`setTimeout`), so it
   * is cleared on stop and never fires after it; `update(true)` after a new start sets it again.
   */
  deadline(spec: DeadlineSpec): Deadline<Handle> {
    return new Deadline<Handle>(
      {
        now: () => this.scheduler.now(),
        set: (fn, ms) => this.setTimeout(fn, ms),
        clear: (h) => this.clearTimeout(h),
      },
      spec,
    );
  }

  /** Runs `fn` when this run stops (unsubscribe, close a socket). Runs at once when stopped. */
  onStop(fn: () => void): void {
    if (!this.ctrl) fn();
    else this.cleanups.push(fn);
  }

  /** Number of live timers, for tests. */
  get timerCount(): number {
    return this.timeouts.size + this.intervals.size;
  }
}
