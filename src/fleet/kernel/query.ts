import { useCallback, useEffect, useState, useSyncExternalStore } from 'react';
import { isPlainObject, replaceEqualDeep } from './share';

/**
 * On-demand reads (files, file info, settings, stats, programs, thumbnails) go through one
 * query layer per machine: keyed under the machine's id, with stale times, no two requests for
 * the same key at once, invalidation after a command, cancellation on stop (the request's
 * AbortSignal), and a bounded cache (least recently used unobserved entries go first, and any
 * unobserved entry after `gcTimeMs`). The live link (polls, sockets) stays the session's.
 *
 * The rules, as the views and sessions rely on them:
 * - a read of a key with a read in flight joins it; a fresh answer is returned without a request;
 * - an answer is written with structural sharing (`replaceEqualDeep`) against the previous one;
 * - a failed read keeps the previous answer and shows its error; nothing is retried behind the
 *   user's back, and nothing is refetched on window focus or reconnect;
 * - `invalidate` marks every read under a key prefix stale and reads again those being watched
 *   (a read in flight that already has an answer is cancelled and started again, so what is
 *   shown was read after the command);
 * - a cancelled read (stop, the last watcher of a key leaving) has its signal aborted, and its
 *   late answer is never written.
 */

export type QueryKey = readonly unknown[];

export interface QueryOptions {
  /** How long an answer counts as fresh (no refetch on a new viewer). Default 10 s. */
  staleTimeMs?: number;
  /** Refetch this often while something shows it (ms); off by default. */
  refetchIntervalMs?: number;
  /** False: wait (a missing argument, a machine not online). */
  enabled?: boolean;
}

export interface MachineQueriesOptions {
  /** Most entries kept; beyond it the least recently used unobserved ones are dropped. */
  maxEntries?: number;
  /** An unobserved entry is dropped after this long. */
  gcTimeMs?: number;
}

export type Fetcher<T> = (signal: AbortSignal) => Promise<T>;

export interface QueryView<T> {
  data: T | undefined;
  /** The last error, when the last read failed. */
  error: Error | null;
  /** No answer yet and one is being read. */
  loading: boolean;
  /** A read is in flight (also when refreshing shown data). */
  fetching: boolean;
  /** When the shown answer arrived (ms since epoch), 0 if none. */
  updatedAt: number;
  refetch: () => void;
}

const DEFAULT_STALE_MS = 10_000;
const DEFAULT_GC_MS = 5 * 60_000;

/** Why a read's promise rejected when the layer cancelled it (stop, a watcher leaving). */
export class CancelledError extends Error {
  constructor(
    /** Its entry went back to the state before the read. */
    readonly revert: boolean,
    /** Superseded or dropped: a read started again in its place takes over its callers. */
    readonly silent: boolean,
  ) {
    super('CancelledError');
  }
}

const noop = () => undefined;

function isValidTimeout(ms: unknown): ms is number {
  return typeof ms === 'number' && ms >= 0 && ms !== Infinity;
}

/** A stable string for a key: plain objects with their keys sorted. */
function hashKey(key: QueryKey): string {
  return JSON.stringify(key, (_, val: unknown) =>
    isPlainObject(val)
      ? Object.keys(val)
          .sort()
          .reduce<Record<string, unknown>>((out, k) => {
            out[k] = val[k];
            return out;
          }, {})
      : val,
  );
}

/** `b` is a prefix of `a` (arrays item by item, objects key by key, deeply). */
function partialMatchKey(a: unknown, b: unknown): boolean {
  if (a === b) return true;
  if (typeof a !== typeof b) return false;
  if (a && b && typeof a === 'object' && typeof b === 'object') {
    if (Array.isArray(a) && Array.isArray(b)) {
      if (b.length > a.length) return false;
      return b.every((item, i) => partialMatchKey(a[i], item));
    }
    const x = a as Record<string, unknown>;
    const y = b as Record<string, unknown>;
    return Object.keys(y).every((k) => partialMatchKey(x[k], y[k]));
  }
  return false;
}

/** The page is shown (interval refetches wait while it is hidden). */
function pageShown(): boolean {
  return typeof document === 'undefined' || document.visibilityState !== 'hidden';
}

interface EntryState<T> {
  data: T | undefined;
  /** When `data` was written (ms since epoch), 0 if never. */
  updatedAt: number;
  error: Error | null;
  /** pending: no answer and no error yet. */
  status: 'pending' | 'success' | 'error';
  fetching: boolean;
  /** Stale whatever its age (invalidated, or the last read failed). */
  invalidated: boolean;
}

interface Run<T> {
  readonly promise: Promise<T>;
  /** Rejects the run's promise at once and aborts its signal (no-op once it answered). */
  cancel(err: CancelledError): void;
  /** What a cancel with revert goes back to: the state before the read (and any `set` since). */
  revert: EntryState<T>;
}

/** One key's cached answer, its read in flight, and the watchers showing it. */
class Entry<T> {
  state: EntryState<T> = {
    data: undefined,
    updatedAt: 0,
    error: null,
    status: 'pending',
    fetching: false,
    invalidated: false,
  };
  /** The latest read function given for this key (by a fetch or a watcher). */
  fn: Fetcher<T> | undefined;
  run: Run<T> | null = null;
  readonly observers: QueryWatch<T>[] = [];
  private gcTimer: ReturnType<typeof setTimeout> | undefined;

  constructor(
    private readonly owner: MachineQueries,
    readonly key: QueryKey,
    readonly hash: string,
  ) {
    this.scheduleGc();
  }

  private setState(next: EntryState<T>): void {
    this.state = next;
    for (const o of this.observers.slice()) o.onEntryUpdate();
  }

  isStaleByTime(staleTimeMs: number): boolean {
    const s = this.state;
    if (s.data === undefined || s.invalidated) return true;
    return Date.now() >= s.updatedAt + staleTimeMs;
  }

  isActive(): boolean {
    return this.observers.some((o) => o.enabled);
  }

  invalidate(): void {
    if (!this.state.invalidated) this.setState({ ...this.state, invalidated: true });
  }

  /** Writes an answer (shared with the previous one); `manual`: not a read's, a read in flight goes on. */
  write(data: T, manual: boolean): T {
    const shared = replaceEqualDeep(this.state.data, data);
    const next: EntryState<T> = {
      ...this.state,
      data: shared,
      updatedAt: Date.now(),
      error: null,
      status: 'success',
      invalidated: false,
      fetching: manual ? this.state.fetching : false,
    };
    if (manual && this.run) this.run.revert = next;
    this.setState(next);
    return shared;
  }

  /**
   * Reads the key, or joins the read in flight. `cancelRefetch`: a read in flight of a key that
   * has an answer is cancelled and started again (its callers get the new read's answer).
   */
  fetch(fn: Fetcher<T> | undefined, cancelRefetch = false): Promise<T> {
    if (this.run) {
      if (this.state.data !== undefined && cancelRefetch) this.run.cancel(new CancelledError(false, true));
      else return this.run.promise;
    }
    if (fn) this.fn = fn;
    const read = this.fn ?? this.observers.find((o) => o.fn)?.fn;
    const controller = new AbortController();
    const revert = this.state;
    this.setState({
      ...this.state,
      fetching: true,
      ...(this.state.data === undefined && { error: null, status: 'pending' as const }),
    });

    let settled = false;
    let settle!: { resolve: (v: T) => void; reject: (e: unknown) => void };
    const answer = new Promise<T>((resolve, reject) => (settle = { resolve, reject }));
    // The caller's promise: the answer written (or the error shown), unless the read was cancelled.
    const outcome = async (): Promise<T> => {
      try {
        const data = await answer;
        if (data === undefined) throw new Error(`${this.hash} data is undefined`);
        this.write(data, false);
        return data;
      } catch (e) {
        if (e instanceof CancelledError) {
          if (e.silent) {
            // Started again in its place: this read's callers get that one's answer.
            if (this.run && this.run !== run) return this.run.promise;
            throw e;
          }
          if (this.state.data === undefined) throw e;
          return this.state.data;
        }
        this.setState({
          ...this.state,
          error: e as Error,
          status: 'error',
          fetching: false,
          invalidated: true,
        });
        throw e;
      } finally {
        if (this.run === run) this.run = null;
        this.scheduleGc();
      }
    };
    const run: Run<T> = {
      revert,
      cancel: (err) => {
        if (settled) return;
        settled = true;
        settle.reject(err);
        if (this.run === run) this.run = null;
        if (err.revert) this.setState({ ...run.revert, fetching: false });
        controller.abort();
      },
      promise: outcome(),
    };
    this.run = run;

    let pending: Promise<T>;
    try {
      pending = read ? read(controller.signal) : Promise.reject(new Error(`Missing queryFn: '${this.hash}'`));
    } catch (e) {
      pending = Promise.reject(e);
    }
    Promise.resolve(pending).then(
      (v) => {
        if (settled) return;
        settled = true;
        settle.resolve(v);
      },
      (e: unknown) => {
        if (settled) return;
        settled = true;
        settle.reject(e);
      },
    );
    return run.promise;
  }

  addObserver(o: QueryWatch<T>): void {
    if (this.observers.includes(o)) return;
    this.observers.push(o);
    this.clearGc();
  }

  removeObserver(o: QueryWatch<T>): void {
    const i = this.observers.indexOf(o);
    if (i === -1) return;
    this.observers.splice(i, 1);
    if (this.observers.length === 0) {
      // Nobody shows it any more: the read in flight is cancelled (its request aborted).
      this.run?.cancel(new CancelledError(true, false));
      this.scheduleGc();
    }
  }

  /** Dropped from the cache: its timer cleared, a read in flight cancelled. */
  destroy(): void {
    this.clearGc();
    this.run?.cancel(new CancelledError(false, true));
  }

  private scheduleGc(): void {
    this.clearGc();
    const ms = this.owner.gcTimeMs;
    if (!isValidTimeout(ms)) return;
    this.gcTimer = setTimeout(() => {
      if (this.observers.length === 0 && !this.state.fetching) this.owner.remove(this);
    }, ms);
  }

  private clearGc(): void {
    if (this.gcTimer === undefined) return;
    clearTimeout(this.gcTimer);
    this.gcTimer = undefined;
  }
}

interface WatchOptions<T> {
  key: QueryKey;
  hash: string;
  fn: Fetcher<T>;
  staleTimeMs: number;
  enabled: boolean;
  refetchInterval: number | false;
}

/**
 * One watcher of one key (what a view on screen is): while subscribed it counts as an observer of
 * its entry (keeping it from gc and trim, and refetched on invalidation), reads it when stale, and
 * refetches every `refetchIntervalMs`. `view` is a stable object, replaced only when what it shows
 * changes.
 */
export class QueryWatch<T> {
  private entry!: Entry<T>;
  private options!: WatchOptions<T>;
  private readonly listeners = new Set<() => void>();
  private interval: ReturnType<typeof setInterval> | undefined;
  private currentInterval: number | false = false;
  view!: QueryView<T>;
  /** Reads again now (a read in flight of shown data is started again), whatever `enabled` says. */
  readonly refetch = (): void => void this.fetchNow(true);

  constructor(
    /** The cache of the machine watched: a watch never moves to another machine's. */
    readonly queries: MachineQueries,
    parts: readonly unknown[],
    fn: Fetcher<T>,
    opts: QueryOptions = {},
  ) {
    this.setOptions(parts, fn, opts);
  }

  get fn(): Fetcher<T> {
    return this.options.fn;
  }

  get enabled(): boolean {
    return this.options.enabled;
  }

  /** New key, read function or options (a view's render): a new key is read at once when stale. */
  setOptions(parts: readonly unknown[], fn: Fetcher<T>, opts: QueryOptions = {}): void {
    const prevEntry = this.entry as Entry<T> | undefined;
    const prev = this.options as WatchOptions<T> | undefined;
    const key = this.queries.key(...parts);
    this.options = {
      key,
      hash: hashKey(key),
      fn,
      staleTimeMs: opts.staleTimeMs ?? DEFAULT_STALE_MS,
      enabled: opts.enabled ?? true,
      refetchInterval: opts.refetchIntervalMs ?? false,
    };
    this.updateEntry();
    this.entry.fn = fn;
    const mounted = this.listeners.size > 0;
    if (mounted && (this.entry !== prevEntry || prev?.enabled === false) && this.isStale()) {
      void this.fetchNow(false);
    }
    this.updateView();
    const next = this.options.refetchInterval;
    if (
      mounted &&
      (this.entry !== prevEntry || this.options.enabled !== prev?.enabled || next !== this.currentInterval)
    ) {
      this.updateInterval(next);
    }
  }

  /** Watches: the first listener makes this an observer of its entry (read now when stale). */
  subscribe(listener: () => void): () => void {
    this.listeners.add(listener);
    if (this.listeners.size === 1) {
      this.entry.addObserver(this);
      if (this.isStale()) void this.fetchNow(false);
      else this.updateView();
      this.updateInterval(this.options.refetchInterval);
    }
    return () => {
      this.listeners.delete(listener);
      if (this.listeners.size === 0) this.stop();
    };
  }

  /** The entry changed (an answer, an error, a read started, an invalidation). */
  onEntryUpdate(): void {
    this.updateView();
    if (this.listeners.size > 0) this.updateInterval(this.options.refetchInterval);
  }

  private stop(): void {
    this.listeners.clear();
    this.clearInterval();
    this.entry.removeObserver(this);
  }

  private isStale(): boolean {
    return this.options.enabled && this.entry.isStaleByTime(this.options.staleTimeMs);
  }

  private updateEntry(): void {
    const entry = this.queries.build<T>(this.options.key, this.options.hash);
    if (entry === this.entry) return;
    const prev = this.entry as Entry<T> | undefined;
    this.entry = entry;
    if (this.listeners.size > 0) {
      prev?.removeObserver(this);
      entry.addObserver(this);
    }
  }

  private fetchNow(cancelRefetch: boolean): Promise<void> {
    this.updateEntry();
    const done = this.entry.fetch(this.options.fn, cancelRefetch).then(noop, noop);
    if (!cancelRefetch) return done;
    return done.then(() => this.updateView());
  }

  private updateView(): void {
    const s = this.entry.state;
    const prev = this.view as QueryView<T> | undefined;
    const loading = s.status === 'pending' && s.fetching;
    if (
      prev &&
      prev.data === s.data &&
      prev.error === s.error &&
      prev.loading === loading &&
      prev.fetching === s.fetching &&
      prev.updatedAt === s.updatedAt
    ) {
      return;
    }
    this.view = {
      data: s.data,
      error: s.error,
      loading,
      fetching: s.fetching,
      updatedAt: s.updatedAt,
      refetch: this.refetch,
    };
    for (const l of [...this.listeners]) l();
  }

  private updateInterval(ms: number | false): void {
    this.clearInterval();
    this.currentInterval = ms;
    if (ms === 0 || !this.options.enabled || !isValidTimeout(ms)) return;
    this.interval = setInterval(() => {
      if (pageShown()) void this.fetchNow(false);
    }, ms);
  }

  private clearInterval(): void {
    if (this.interval === undefined) return;
    clearInterval(this.interval);
    this.interval = undefined;
  }
}

export class MachineQueries {
  readonly gcTimeMs: number;
  private readonly maxEntries: number;
  private readonly entries = new Map<string, Entry<unknown>>();

  constructor(
    readonly machineId: string,
    opts: MachineQueriesOptions = {},
  ) {
    this.maxEntries = opts.maxEntries ?? 200;
    this.gcTimeMs = opts.gcTimeMs ?? DEFAULT_GC_MS;
  }

  /** The full key of a read of this machine. */
  key(...parts: readonly unknown[]): QueryKey {
    return [this.machineId, ...parts];
  }

  /** One read (deduplicated with any in flight; cached for `staleTimeMs`). */
  fetch<T>(parts: readonly unknown[], fn: Fetcher<T>, opts: QueryOptions = {}): Promise<T> {
    const key = this.key(...parts);
    const entry = this.build<T>(key, hashKey(key));
    return entry.isStaleByTime(opts.staleTimeMs ?? DEFAULT_STALE_MS)
      ? entry.fetch(fn)
      : Promise.resolve(entry.state.data as T);
  }

  /** The cached answer, if any (no request). */
  peek<T>(parts: readonly unknown[]): T | undefined {
    return this.find<T>(parts)?.state.data;
  }

  /** The cached answer and when it was written (ms since epoch), if any (no request). */
  cached<T>(parts: readonly unknown[]): { data: T; updatedAt: number } | undefined {
    const s = this.find<T>(parts)?.state;
    return s && s.data !== undefined ? { data: s.data, updatedAt: s.updatedAt } : undefined;
  }

  /**
   * Writes an answer got another way (an upload's verified listing): fresh from now, shown by
   * every watcher of the key. A read in flight of the key goes on and writes its answer after.
   */
  set<T>(parts: readonly unknown[], data: T): void {
    if (data === undefined) return;
    const key = this.key(...parts);
    this.build<T>(key, hashKey(key)).write(data, true);
  }

  /** Marks every read under `parts` stale and refetches those on screen. */
  invalidate(parts: readonly unknown[] = []): Promise<void> {
    const prefix = this.key(...parts);
    const matched = [...this.entries.values()].filter((e) => partialMatchKey(e.key, prefix));
    for (const e of matched) e.invalidate();
    const reads = matched.filter((e) => e.isActive()).map((e) => e.fetch(undefined, true).catch(noop));
    return Promise.all(reads).then(noop);
  }

  /** Drops everything (the session stopped): in-flight reads are cancelled. */
  clear(): void {
    const all = [...this.entries.values()];
    for (const e of all) e.run?.cancel(new CancelledError(true, false));
    for (const e of all) this.remove(e);
  }

  /** Number of cached entries, for tests. */
  get size(): number {
    return this.entries.size;
  }

  /** A watcher of one read (what `useMachineQuery` is made of): see `QueryWatch`. */
  watch<T>(parts: readonly unknown[], fn: Fetcher<T>, opts: QueryOptions = {}): QueryWatch<T> {
    return new QueryWatch(this, parts, fn, opts);
  }

  /** The entry of a key, made (and the cache trimmed) if there is none. Internal: for QueryWatch. */
  build<T>(key: QueryKey, hash: string): Entry<T> {
    let entry = this.entries.get(hash) as Entry<T> | undefined;
    if (!entry) {
      entry = new Entry<T>(this, key, hash);
      this.entries.set(hash, entry as Entry<unknown>);
      this.trim();
    }
    return entry;
  }

  /** Drops an entry (gc, trim, clear). Internal: for Entry. */
  remove(entry: Entry<unknown>): void {
    if (this.entries.get(entry.hash) !== entry) return;
    entry.destroy();
    this.entries.delete(entry.hash);
  }

  private find<T>(parts: readonly unknown[]): Entry<T> | undefined {
    return this.entries.get(hashKey(this.key(...parts))) as Entry<T> | undefined;
  }

  private trim(): void {
    const all = [...this.entries.values()];
    if (all.length <= this.maxEntries) return;
    const idle = all
      // Never the entry being added or read (no answer yet), never one on screen.
      .filter((e) => e.observers.length === 0 && e.state.status !== 'pending' && !e.state.fetching)
      .sort((a, b) => a.state.updatedAt - b.state.updatedAt);
    for (const e of idle.slice(0, all.length - this.maxEntries)) this.remove(e);
  }
}

/** A React view of one read of a machine: shown from cache at once, refetched when stale. */
export function useMachineQuery<T>(
  queries: MachineQueries,
  parts: readonly unknown[],
  fn: Fetcher<T>,
  opts: QueryOptions = {},
): QueryView<T> {
  // One watch per machine's cache: re-rendered with another machine (the same view shown for
  // machine B after A), a new watch of B's cache, never B's reads in A's.
  const [held, setHeld] = useState(() => queries.watch(parts, fn, opts));
  let watch = held;
  if (held.queries !== queries) {
    watch = queries.watch(parts, fn, opts);
    setHeld(watch);
  }
  useEffect(() => {
    watch.setOptions(parts, fn, opts);
  });
  const subscribe = useCallback((onChange: () => void) => watch.subscribe(onChange), [watch]);
  const view = () => watch.view;
  return useSyncExternalStore(subscribe, view, view);
}
