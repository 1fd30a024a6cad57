import { createStore, type StoreApi } from 'zustand/vanilla';
import { describeError, LinkError } from '../../fleet/errors';
import { Poller, type Visibility } from '../../fleet/link';
import type { TouchcutClient } from './client';
import { isUnauthorized } from './client';
import type { Monitor, OpenData, Stats, UnitsChoice } from './wire';

/**
 * On-demand feeds of a TouchCut session: monitor (axes / I/O), screenshot, stats, programs and
 * unloader. Each has its own vanilla store; views acquire a feed while they are on screen.
 */

export interface FeedHost {
  client: TouchcutClient;
  visibility: Visibility;
  now: () => number;
  units: () => UnitsChoice;
  /** False while the machine needs a login or the session is stopped: feeds send nothing. */
  canRequest: () => boolean;
  /** A 401: the session decides (needs login). */
  authFailed: (e: unknown) => void;
}

// ---------------------------------------------------------------------------------------------
// monitor

export const MONITOR_INTERVAL_MS = 500;

export interface MonitorState {
  data: Monitor | null;
  at: number | null;
  error: string | null;
  fields: string[];
}

export class MonitorFeed {
  readonly store: StoreApi<MonitorState> = createStore<MonitorState>(() => ({
    data: null,
    at: null,
    error: null,
    fields: [],
  }));
  private users = 0;
  private readonly poller: Poller;

  constructor(private readonly host: FeedHost) {
    this.poller = new Poller({
      run: () => this.poll(),
      // About twice a second while visible (the Poller slows to ≥ 10 s while the page is hidden).
      intervalMs: () => MONITOR_INTERVAL_MS,
      visibility: host.visibility,
      onError: (e) => {
        if (isUnauthorized(e)) this.host.authFailed(e);
        this.store.setState({ error: describeError(e) });
      },
      retryDelayMs: (n) => Math.min(10_000, 1000 * 2 ** (n - 1)),
    });
  }

  /** `fields` for the request ("axes.*", "io.din", …): only what is on screen. */
  setFields(fields: string[]): void {
    const prev = this.store.getState().fields;
    if (prev.length === fields.length && prev.every((f, i) => f === fields[i])) return;
    this.store.setState({ fields });
    this.poller.kick();
  }

  acquire(): () => void {
    this.users++;
    if (this.users === 1) this.poller.start(0);
    let released = false;
    return () => {
      if (released) return;
      released = true;
      this.users--;
      if (this.users === 0) this.poller.stop();
    };
  }

  get polls(): number {
    return this.poller.started;
  }

  stop(): void {
    this.users = 0;
    this.poller.stop();
  }

  private async poll(): Promise<void> {
    if (!this.host.canRequest()) return;
    const { fields } = this.store.getState();
    if (fields.length === 0) return;
    const data = await this.host.client.monitor(fields, this.host.units());
    this.store.setState({ data, at: this.host.now(), error: null });
  }
}

// ---------------------------------------------------------------------------------------------
// screenshot

/** The controller serves a new image at most once a second: never ask more often. */
export const SCREENSHOT_MIN_GAP_MS = 1000;
/** Fleet tile thumbnails: at most every 10 s. */
export const THUMBNAIL_INTERVAL_MS = 10_000;

export interface ScreenshotState {
  blob: Blob | null;
  /** When the image arrived (ms since epoch). */
  at: number | null;
  error: string | null;
  loading: boolean;
}

/**
 * One screenshot stream per machine, shared by every viewer (machine page, fleet tile): at most
 * one request per second, never two at once, none while the page is hidden or nobody watches.
 */
export class ScreenshotFeed {
  readonly store: StoreApi<ScreenshotState> = createStore<ScreenshotState>(() => ({
    blob: null,
    at: null,
    error: null,
    loading: false,
  }));
  private readonly subs = new Map<number, number>();
  private nextId = 0;
  private timer: ReturnType<typeof setTimeout> | null = null;
  private inFlight = false;
  private lastStart: number | null = null;
  private unsubscribeVis: (() => void) | null = null;
  /** Requests started (tests, benchmarks). */
  requests = 0;
  /** Start times of every request (ms), for tests. */
  readonly starts: number[] = [];

  constructor(private readonly host: FeedHost) {}

  /** Watch the screen at `intervalMs` (≥ 1 s). Returns the unsubscribe function. */
  subscribe(intervalMs = SCREENSHOT_MIN_GAP_MS): () => void {
    const id = ++this.nextId;
    this.subs.set(id, Math.max(SCREENSHOT_MIN_GAP_MS, intervalMs));
    if (!this.unsubscribeVis) this.unsubscribeVis = this.host.visibility.subscribe(() => this.schedule());
    this.schedule();
    return () => {
      this.subs.delete(id);
      if (this.subs.size === 0) {
        this.clear();
        this.unsubscribeVis?.();
        this.unsubscribeVis = null;
      } else this.schedule();
    };
  }

  get watching(): boolean {
    return this.subs.size > 0;
  }

  /** Retry soon (after login, after a reconnect). */
  kick(): void {
    this.schedule();
  }

  stop(): void {
    this.subs.clear();
    this.clear();
    this.unsubscribeVis?.();
    this.unsubscribeVis = null;
  }

  private interval(): number {
    return Math.min(...this.subs.values());
  }

  private clear(): void {
    if (this.timer) clearTimeout(this.timer);
    this.timer = null;
  }

  private schedule(): void {
    this.clear();
    if (this.subs.size === 0 || this.inFlight || this.host.visibility.hidden()) return;
    const now = this.host.now();
    const due = this.lastStart === null ? now : this.lastStart + this.interval();
    const earliest = this.lastStart === null ? now : this.lastStart + SCREENSHOT_MIN_GAP_MS;
    const delay = Math.max(0, due - now, earliest - now);
    this.timer = setTimeout(() => void this.fetch(), delay);
  }

  private async fetch(): Promise<void> {
    this.timer = null;
    if (this.subs.size === 0 || this.inFlight || this.host.visibility.hidden()) return;
    if (!this.host.canRequest()) {
      // Not connected / needs login: look again later (no request is sent meanwhile).
      this.timer = setTimeout(() => this.schedule(), 2000);
      return;
    }
    const now = this.host.now();
    if (this.lastStart !== null && now - this.lastStart < SCREENSHOT_MIN_GAP_MS) {
      this.schedule();
      return;
    }
    this.inFlight = true;
    this.lastStart = now;
    this.requests++;
    this.starts.push(now);
    if (this.starts.length > 100) this.starts.shift();
    this.store.setState({ loading: true });
    let failed = false;
    try {
      const shot = await this.host.client.screenshot();
      this.store.setState({ blob: shot.blob, at: this.host.now(), error: null, loading: false });
    } catch (e) {
      failed = true;
      if (isUnauthorized(e)) this.host.authFailed(e);
      this.store.setState({ error: describeError(e), loading: false });
    } finally {
      this.inFlight = false;
    }
    if (failed) {
      // Back off: do not hammer a failing controller with one request per second.
      this.clear();
      if (this.subs.size > 0 && !this.host.visibility.hidden())
        this.timer = setTimeout(() => this.schedule(), 5000);
      return;
    }
    this.schedule();
  }
}

// ---------------------------------------------------------------------------------------------
// stats

export interface StatsRequest {
  startDate: string;
  endBeforeDate: string;
  condensed: boolean;
}

export interface StatsState {
  request: StatsRequest | null;
  data: Stats | null;
  at: number | null;
  loading: boolean;
  error: string | null;
}

export class StatsLoader {
  readonly store: StoreApi<StatsState> = createStore<StatsState>(() => ({
    request: null,
    data: null,
    at: null,
    loading: false,
    error: null,
  }));
  private seq = 0;

  constructor(private readonly host: FeedHost) {}

  async load(req: StatsRequest): Promise<void> {
    const seq = ++this.seq;
    this.store.setState({ request: req, loading: true, error: null });
    try {
      if (!this.host.canRequest()) throw new LinkError('offline', 'The machine is not connected');
      const data = await this.host.client.stats({ ...req, units: this.host.units() });
      if (seq !== this.seq) return;
      this.store.setState({ data, at: this.host.now(), loading: false });
    } catch (e) {
      if (seq !== this.seq) return;
      if (isUnauthorized(e)) this.host.authFailed(e);
      this.store.setState({ loading: false, error: describeError(e) });
    }
  }
}

// ---------------------------------------------------------------------------------------------
// programs and unloader ("interface subject to change": generic data)

export interface OpenDataState {
  data: OpenData | null;
  at: number | null;
  loading: boolean;
  error: string | null;
  offset: number;
  limit: number;
  history: { startDate: string; endBeforeDate: string } | null;
}

/** Deep merge for `onlyChangedData` refreshes: objects merge key by key, arrays and values replace. */
export function mergeChanged(base: unknown, changed: unknown): unknown {
  if (!base || !changed || typeof base !== 'object' || typeof changed !== 'object') return changed;
  if (Array.isArray(base) || Array.isArray(changed)) return changed;
  const out: Record<string, unknown> = { ...(base as Record<string, unknown>) };
  for (const [k, v] of Object.entries(changed as Record<string, unknown>)) out[k] = mergeChanged(out[k], v);
  return out;
}

export const PROGRAMS_REFRESH_MS = 5000;

export class OpenDataFeed {
  readonly store: StoreApi<OpenDataState> = createStore<OpenDataState>(() => ({
    data: null,
    at: null,
    loading: false,
    error: null,
    offset: 0,
    limit: 25,
    history: null,
  }));
  private users = 0;
  private readonly poller: Poller;
  private full = false;

  constructor(
    private readonly host: FeedHost,
    private readonly kind: 'programs' | 'unloader',
  ) {
    this.poller = new Poller({
      run: () => this.poll(),
      intervalMs: () => PROGRAMS_REFRESH_MS,
      visibility: host.visibility,
      onError: (e) => {
        if (isUnauthorized(e)) this.host.authFailed(e);
        this.store.setState({ error: describeError(e), loading: false });
      },
    });
  }

  acquire(): () => void {
    this.users++;
    if (this.users === 1) {
      this.full = false;
      this.poller.start(0);
    }
    let released = false;
    return () => {
      if (released) return;
      released = true;
      this.users--;
      if (this.users === 0) this.poller.stop();
    };
  }

  page(offset: number, limit: number): void {
    this.store.setState({ offset: Math.max(0, offset), limit });
    this.reload();
  }

  setHistory(h: { startDate: string; endBeforeDate: string } | null): void {
    this.store.setState({ history: h });
    this.reload();
  }

  reload(): void {
    this.full = false;
    this.poller.kick();
  }

  stop(): void {
    this.users = 0;
    this.poller.stop();
  }

  private async poll(): Promise<void> {
    if (!this.host.canRequest()) return;
    const s = this.store.getState();
    const units = this.host.units();
    if (this.kind === 'programs') {
      const changedOnly = this.full && s.data !== null;
      this.store.setState({ loading: !changedOnly });
      const data = await this.host.client.programs({
        offset: s.offset,
        limit: s.limit,
        onlyChangedData: changedOnly,
        units,
      });
      this.full = true;
      const merged = changedOnly ? (mergeChanged(this.store.getState().data, data) as OpenData) : data;
      this.store.setState({ data: merged, at: this.host.now(), loading: false, error: null });
    } else {
      this.store.setState({ loading: !this.full });
      const data = await this.host.client.unloader({
        history: s.history !== null,
        startDate: s.history?.startDate,
        endBeforeDate: s.history?.endBeforeDate,
        units,
      });
      this.full = true;
      this.store.setState({ data, at: this.host.now(), loading: false, error: null });
    }
  }
}
