/**
 * Time as one service (issue 34): every timer of the page's kernel and its views goes through one
 * `Scheduler`. Periodic work of one period shares one tick (`every`); one-shots due at the same
 * moment share one timer (`after`: polls on the shared grid of a period wake the page once, not
 * once per machine); a deadline that data keeps pushing back keeps its timer (`deadline`: it fires
 * early, finds the moment moved on, and is set again for the rest) instead of a timer per message.
 * Injectable: tests give it a `ManualClock` or run it on vitest's fake timers (the default host
 * reads the page's timers at each call).
 */

/** The timers a scheduler sets and the clock it reads. */
export interface TimerHost {
  now(): number;
  setTimeout(fn: () => void, ms: number): unknown;
  clearTimeout(handle: unknown): void;
  setInterval(fn: () => void, ms: number): unknown;
  clearInterval(handle: unknown): void;
}

type Handle = ReturnType<typeof setTimeout>;

/** The page's (or Node's) timers, looked up at each call so that fake timers installed later apply. */
export const pageTimers: TimerHost = {
  now: () => Date.now(),
  setTimeout: (fn, ms) => globalThis.setTimeout(fn, ms),
  clearTimeout: (h) => globalThis.clearTimeout(h as Handle),
  setInterval: (fn, ms) => globalThis.setInterval(fn, ms),
  clearInterval: (h) => globalThis.clearInterval(h as Handle),
};

/** Stops what it was returned for; a second call does nothing. */
export type Cancel = () => void;

/** A one-shot timer source (a scheduler's, or a lifecycle run's: nothing set once it stopped). */
export interface OneShots<H> {
  now(): number;
  set(fn: () => void, ms: number): H | null;
  clear(handle: H | null): void;
}

/** What a deadline watches: its moment (null: none now), and the work due then. */
export interface DeadlineSpec {
  /** When the work is due (ms, the scheduler's clock), read again whenever the timer fires. */
  due: () => number | null;
  /** Runs once the moment has come. */
  fire: () => void;
  /** The clock `due` is read on (default the scheduler's). */
  now?: () => number;
}

/**
 * A moment that data moves (the end of a liveness window, a heartbeat's next check). `update()`
 * after data re-reads the moment: a later one keeps the timer (it fires, finds the moment not yet
 * come, and is set for the rest), an earlier one (or `force`) sets it anew. After `fire`, the next
 * moment, if still ahead, is set again; a moment already past is not fired twice.
 */
export class Deadline<H = unknown> {
  private timer: H | null = null;
  private armedFor = Infinity;
  private readonly now: () => number;

  constructor(
    private readonly t: OneShots<H>,
    private readonly spec: DeadlineSpec,
  ) {
    this.now = spec.now ?? (() => t.now());
  }

  /** True while a timer is set. */
  get armed(): boolean {
    return this.timer !== null;
  }

  /** When the set timer fires (Infinity: none), for tests. */
  get firesAt(): number {
    return this.armedFor;
  }

  /** The moment may have moved: set the timer anew only when it came nearer (or `force`). */
  update(force = false): void {
    const due = this.spec.due();
    if (due === null) {
      this.cancel();
      return;
    }
    if (!force && this.timer !== null && this.armedFor <= due) return;
    this.arm(due);
  }

  cancel(): void {
    if (this.timer !== null) this.t.clear(this.timer);
    this.timer = null;
    this.armedFor = Infinity;
  }

  private arm(due: number): void {
    this.cancel();
    const now = this.now();
    const left = Math.max(0, due - now);
    this.timer = this.t.set(() => this.fired(), left);
    this.armedFor = this.timer === null ? Infinity : now + left;
  }

  private fired(): void {
    this.timer = null;
    this.armedFor = Infinity;
    const due = this.spec.due();
    if (due === null) return;
    if (this.now() < due) {
      this.arm(due);
      return;
    }
    this.spec.fire();
    if (this.timer !== null) return;
    const next = this.spec.due();
    if (next !== null && next > this.now()) this.arm(next);
  }
}

/**
 * Runs every callback of `fns` as it is now, skipping one cancelled by an earlier one meanwhile
 * (nothing runs after its cancel); an error of one neither stops the others nor is lost (thrown
 * after them).
 */
function runAll(fns: Set<() => void>): void {
  let failed: { error: unknown } | null = null;
  for (const fn of [...fns]) {
    if (!fns.has(fn)) continue;
    try {
      fn();
    } catch (error) {
      failed ??= { error };
    }
  }
  if (failed) throw failed.error;
}

export class Scheduler {
  /** One-shots by the moment they are due: one host timer per moment. */
  private readonly moments = new Map<number, { fns: Set<() => void>; handle: unknown }>();
  /** Periodic work by period: one host interval per period. */
  private readonly ticks = new Map<number, { fns: Set<() => void>; handle: unknown }>();

  constructor(readonly host: TimerHost = pageTimers) {}

  now(): number {
    return this.host.now();
  }

  /** `fn` once, `ms` from now; one-shots due at the same moment share one timer. */
  after(ms: number, fn: () => void): Cancel {
    const at = this.now() + Math.max(0, Number.isFinite(ms) ? ms : 0);
    let m = this.moments.get(at);
    if (!m) {
      const moment: { fns: Set<() => void>; handle: unknown } = { fns: new Set(), handle: null };
      moment.handle = this.host.setTimeout(() => {
        if (this.moments.get(at) === moment) this.moments.delete(at);
        runAll(moment.fns);
      }, at - this.now());
      this.moments.set(at, moment);
      m = moment;
    }
    const moment = m;
    const entry = (): void => fn();
    moment.fns.add(entry);
    return () => {
      if (!moment.fns.delete(entry) || moment.fns.size > 0) return;
      if (this.moments.get(at) === moment) this.moments.delete(at);
      this.host.clearTimeout(moment.handle);
    };
  }

  /**
   * `fn` every `periodMs` until cancelled. Every subscriber of one period shares one tick (its
   * phase set by the first of them); the tick stops with the last.
   */
  every(periodMs: number, fn: () => void): Cancel {
    let t = this.ticks.get(periodMs);
    if (!t) {
      const tick: { fns: Set<() => void>; handle: unknown } = { fns: new Set(), handle: null };
      tick.handle = this.host.setInterval(() => runAll(tick.fns), periodMs);
      this.ticks.set(periodMs, tick);
      t = tick;
    }
    const tick = t;
    const entry = (): void => fn();
    tick.fns.add(entry);
    return () => {
      if (!tick.fns.delete(entry) || tick.fns.size > 0) return;
      if (this.ticks.get(periodMs) === tick) this.ticks.delete(periodMs);
      this.host.clearInterval(tick.handle);
    };
  }

  /** A deadline re-armed on data (see `Deadline`). */
  deadline(spec: DeadlineSpec): Deadline<Cancel> {
    return new Deadline<Cancel>(
      { now: () => this.now(), set: (fn, ms) => this.after(ms, fn), clear: (c) => c?.() },
      spec,
    );
  }

  /** Host timers set now (moments and ticks), for tests. */
  get pending(): number {
    return this.moments.size + this.ticks.size;
  }
}

/** The page's scheduler: the kernel and the views use it unless given another. */
export const pageScheduler = new Scheduler();

/**
 * A clock for tests that moves only when told (`advance`): a `TimerHost` that counts the timers
 * it was asked to set.
 */
export class ManualClock implements TimerHost {
  private time: number;
  private nextId = 1;
  private readonly timers = new Map<number, { at: number; fn: () => void; every: number | null }>();
  /** Timers set so far (timeouts and intervals). */
  armed = 0;

  constructor(start = 0) {
    this.time = start;
  }

  now(): number {
    return this.time;
  }

  setTimeout(fn: () => void, ms: number): number {
    return this.add(fn, ms, null);
  }

  setInterval(fn: () => void, ms: number): number {
    return this.add(fn, ms, Math.max(1, ms));
  }

  clearTimeout(handle: unknown): void {
    this.timers.delete(handle as number);
  }

  clearInterval(handle: unknown): void {
    this.timers.delete(handle as number);
  }

  /** Timers set and not yet fired or cleared. */
  get live(): number {
    return this.timers.size;
  }

  /** Moves the clock on by `ms`, firing what falls due in order (earliest first, then oldest). */
  advance(ms: number): void {
    const end = this.time + ms;
    for (;;) {
      let next: [number, { at: number; fn: () => void; every: number | null }] | null = null;
      for (const e of this.timers) if (e[1].at <= end && (!next || e[1].at < next[1].at)) next = e;
      if (!next) break;
      const [id, timer] = next;
      this.time = timer.at;
      if (timer.every === null) this.timers.delete(id);
      else timer.at += timer.every;
      timer.fn();
    }
    this.time = end;
  }

  private add(fn: () => void, ms: number, every: number | null): number {
    const id = this.nextId++;
    this.armed++;
    this.timers.set(id, { at: this.time + Math.max(0, ms), fn, every });
    return id;
  }
}
