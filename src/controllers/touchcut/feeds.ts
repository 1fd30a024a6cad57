import type { StoreApi } from 'zustand/vanilla';
import { describeError } from '../../fleet/errors';
import { createSharedStore, type Lifecycle, type PollSpec } from '../../fleet/kernel';
import type { Poller, Visibility } from '../../fleet/link';
import type { TouchcutClient } from './client';
import { isUnauthorized } from './client';
import type { Monitor, UnitsChoice } from './wire';

/**
 * The live feeds of a TouchCut session, shown while a view is on screen: the monitor (axes / I/O,
 * a kernel poll) and the screenshot (its own limiter: the controller serves a new image at most
 * once a second). Both run only within the session's run: their timers are the lifecycle's and
 * an answer that arrives after stop is dropped. On-demand reads (statistics, programs,
 * unloader) are queries: queries.ts.
 */

export {
  mergeChanged,
  OpenDataFeed,
  PROGRAMS_REFRESH_MS,
  StatsLoader,
  type OpenDataState,
  type StatsRequest,
  type StatsState,
} from './queries';

export interface FeedHost {
  client: TouchcutClient;
  visibility: Visibility;
  now: () => number;
  units: () => UnitsChoice;
  /** False while the machine needs a login: feeds send nothing. */
  canRequest: () => boolean;
  /** A 401: the session decides (needs login). */
  authFailed: (e: unknown) => void;
  /** The session's lifecycle: timers are cleared on stop, answers of an ended run are dropped. */
  life: Lifecycle;
}

/** The session's `poll` (KernelSession): declared once, started and stopped with the session. */
export type DeclarePoll = <T>(spec: PollSpec<T>) => Poller;

// ---------------------------------------------------------------------------------------------
// monitor

export const MONITOR_INTERVAL_MS = 500;
/** Nobody watching: the poll only looks whether someone does (no request). */
const MONITOR_IDLE_MS = 10_000;

export interface MonitorState {
  data: Monitor | null;
  at: number | null;
  error: string | null;
  fields: string[];
}

export class MonitorFeed {
  readonly store: StoreApi<MonitorState> = createSharedStore<MonitorState>(() => ({
    data: null,
    at: null,
    error: null,
    fields: [],
  }));
  /** Requests sent (tests, benchmarks). */
  polls = 0;
  private users = 0;
  private failures = 0;
  private readonly poller: Poller;

  constructor(host: FeedHost, poll: DeclarePoll) {
    this.poller = poll({
      name: 'monitor',
      // Only while a view shows it, for the fields on screen, and never while a login is needed.
      when: () => this.users > 0 && this.store.getState().fields.length > 0 && host.canRequest(),
      read: (signal) => {
        this.polls++;
        return host.client.monitor(this.store.getState().fields, host.units(), signal);
      },
      apply: (data) => {
        this.failures = 0;
        this.store.setState({ data, at: host.now(), error: null });
      },
      // About twice a second while watched (the Poller slows to ≥ 10 s while the page is hidden).
      intervalMs: () => (this.users > 0 ? MONITOR_INTERVAL_MS : MONITOR_IDLE_MS),
      failed: (e) => {
        if (isUnauthorized(e)) host.authFailed(e);
        this.store.setState({ error: describeError(e) });
        return Math.min(10_000, 1000 * 2 ** this.failures++);
      },
    });
  }

  /** `fields` for the request ("axes.*", "io.din", …): only what is on screen. */
  setFields(fields: string[]): void {
    const before = this.store.getState();
    this.store.setState({ fields });
    // An equal list keeps the state (structural sharing): no extra request.
    if (this.store.getState() !== before) this.poller.kick();
  }

  acquire(): () => void {
    if (++this.users === 1) this.poller.kick();
    let released = false;
    return () => {
      if (released) return;
      released = true;
      this.users--;
    };
  }
}

// ---------------------------------------------------------------------------------------------
// screenshot

/** The controller serves a new image at most once a second: never ask more often. */
export const SCREENSHOT_MIN_GAP_MS = 1000;
/** Fleet tile thumbnails: at most every 10 s. */
export const THUMBNAIL_INTERVAL_MS = 10_000;
/** After a failed request, or while the machine needs a login, look again after this long. */
const SCREENSHOT_RETRY_MS = 5000;
const SCREENSHOT_WAIT_MS = 2000;
/** Start times kept in `ScreenshotFeed.starts` (the newest): a wall screen runs for weeks. */
export const SCREENSHOT_STARTS_KEPT = 100;

export interface ScreenshotState {
  blob: Blob | null;
  /** When the image arrived (ms since epoch). */
  at: number | null;
  error: string | null;
  loading: boolean;
}

/**
 * One screenshot stream per machine, shared by every viewer (machine page, fleet tile): at most
 * one request per second (start to start, so a slow answer does not stretch the rate), never two
 * at once, none while the page is hidden, nobody watches or the session is stopped.
 */
export class ScreenshotFeed {
  readonly store: StoreApi<ScreenshotState> = createSharedStore<ScreenshotState>(() => ({
    blob: null,
    at: null,
    error: null,
    loading: false,
  }));
  private readonly subs = new Map<number, number>();
  private nextId = 0;
  private timer: ReturnType<Lifecycle['setTimeout']> = null;
  private inFlight = false;
  private lastStart: number | null = null;
  private unsubscribeVis: (() => void) | null = null;
  /** Requests started (tests, benchmarks). */
  requests = 0;
  /** Start times of the last `SCREENSHOT_STARTS_KEPT` requests (ms), for tests. */
  readonly starts: number[] = [];

  constructor(private readonly host: FeedHost) {}

  /** Watch the screen at `intervalMs` (≥ 1 s). Returns the unsubscribe function. */
  subscribe(intervalMs = SCREENSHOT_MIN_GAP_MS): () => void {
    const id = ++this.nextId;
    this.subs.set(id, Math.max(SCREENSHOT_MIN_GAP_MS, intervalMs));
    this.unsubscribeVis ??= this.host.visibility.subscribe(() => this.schedule());
    this.schedule();
    return () => {
      this.subs.delete(id);
      if (this.subs.size > 0) return this.schedule();
      this.later(null);
      this.unsubscribeVis?.();
      this.unsubscribeVis = null;
    };
  }

  get watching(): boolean {
    return this.subs.size > 0;
  }

  /** Look now (after a login, on start). */
  kick(): void {
    this.schedule();
  }

  /** Replaces the pending timer (a timer of the session's run: none once it stopped). */
  private later(fn: (() => void) | null, ms = 0): void {
    this.host.life.clearTimeout(this.timer);
    this.timer = fn && this.host.life.setTimeout(fn, ms);
  }

  private schedule(): void {
    if (this.subs.size === 0 || this.inFlight || this.host.visibility.hidden()) return this.later(null);
    const now = this.host.now();
    const gap = Math.min(...this.subs.values());
    const delay = this.lastStart === null ? 0 : Math.max(0, this.lastStart + gap - now);
    this.later(() => void this.fetch(), delay);
  }

  private async fetch(): Promise<void> {
    this.timer = null;
    if (this.subs.size === 0 || this.inFlight || this.host.visibility.hidden()) return;
    // Needs a login: look again later (no request is sent meanwhile).
    if (!this.host.canRequest()) return this.later(() => this.schedule(), SCREENSHOT_WAIT_MS);
    const now = this.host.now();
    if (this.lastStart !== null && now - this.lastStart < SCREENSHOT_MIN_GAP_MS) return this.schedule();
    const run = this.host.life.current();
    this.inFlight = true;
    this.lastStart = now;
    this.requests++;
    this.starts.push(now);
    if (this.starts.length > SCREENSHOT_STARTS_KEPT) this.starts.shift();
    this.store.setState({ loading: true });
    let failed = false;
    try {
      const shot = await this.host.client.screenshot(run.signal);
      if (run.alive())
        this.store.setState({ blob: shot.blob, at: this.host.now(), error: null, loading: false });
    } catch (e) {
      failed = true;
      if (run.alive()) {
        if (isUnauthorized(e)) this.host.authFailed(e);
        this.store.setState({ error: describeError(e), loading: false });
      }
    } finally {
      this.inFlight = false;
    }
    // Back off after a failure: no request per second to a failing controller.
    if (failed && run.alive()) this.later(() => this.schedule(), SCREENSHOT_RETRY_MS);
    else this.schedule();
  }
}
