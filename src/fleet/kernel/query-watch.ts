import type { Entry, EntryObserver, Fetcher } from './query-entry';
import { hashKey, isValidTimeout, type QueryKey } from './query-key';
import type { Deadline, Scheduler } from './scheduler';

export interface QueryOptions {
  /** How long an answer counts as fresh (no refetch on a new viewer). Default 10 s. */
  staleTimeMs?: number;
  /** Refetch this often while something shows it (ms); off by default. */
  refetchIntervalMs?: number;
  /** False: wait (a missing argument, a machine not online). */
  enabled?: boolean;
}

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

export const DEFAULT_STALE_MS = 10_000;

/** The cache a watch reads (MachineQueries). */
export interface WatchedCache {
  readonly scheduler: Scheduler;
  key(...parts: readonly unknown[]): QueryKey;
  build<T>(key: QueryKey, hash: string): Entry<T>;
}

export const noop = () => undefined;

/** The page is shown (interval refetches wait while it is hidden). */
function pageShown(): boolean {
  return typeof document === 'undefined' || document.visibilityState !== 'hidden';
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
export class QueryWatch<T> implements EntryObserver<T> {
  private entry!: Entry<T>;
  private options!: WatchOptions<T>;
  private readonly listeners = new Set<() => void>();
  /** The next interval refetch (null: none): one deadline, moved on by each update of the entry. */
  private refetchAt: number | null = null;
  private readonly interval: Deadline;
  private currentInterval: number | false = false;
  view!: QueryView<T>;
  /** Reads again now (a read in flight of shown data is started again), whatever `enabled` says. */
  readonly refetch = (): void => void this.fetchNow(true);

  constructor(
    /** The cache of the machine watched: a watch never moves to another machine's. */
    readonly queries: WatchedCache,
    parts: readonly unknown[],
    fn: Fetcher<T>,
    opts: QueryOptions = {},
  ) {
    this.interval = queries.scheduler.deadline({
      due: () => this.refetchAt,
      fire: () => {
        this.refetchAt = this.queries.scheduler.now() + (this.currentInterval || 0);
        if (pageShown()) void this.fetchNow(false);
      },
    });
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

  /** As an interval set anew at each update: the next refetch `ms` after the last update. */
  private updateInterval(ms: number | false): void {
    this.currentInterval = ms;
    if (ms === 0 || !this.options.enabled || !isValidTimeout(ms)) {
      this.clearInterval();
      return;
    }
    this.refetchAt = this.queries.scheduler.now() + ms;
    this.interval.update();
  }

  private clearInterval(): void {
    this.refetchAt = null;
    this.interval.cancel();
  }
}
