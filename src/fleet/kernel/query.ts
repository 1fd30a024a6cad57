import { useCallback, useEffect, useState, useSyncExternalStore } from 'react';
import { CancelledError, Entry, type EntryOwner, type Fetcher } from './query-entry';
import { hashKey, partialMatchKey, type QueryKey } from './query-key';
import {
  DEFAULT_STALE_MS,
  noop,
  QueryWatch,
  type QueryOptions,
  type QueryView,
  type WatchedCache,
} from './query-watch';
import { pageScheduler, type Scheduler } from './scheduler';

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
 *
 * Parts: keys (query-key.ts), one cached read (query-entry.ts), one watcher (query-watch.ts),
 * the cache per machine and the React hook (here).
 */

export { CancelledError, type Fetcher } from './query-entry';
export type { QueryKey } from './query-key';
export { QueryWatch, type QueryOptions, type QueryView } from './query-watch';

export interface MachineQueriesOptions {
  /** Most entries kept; beyond it the least recently used unobserved ones are dropped. */
  maxEntries?: number;
  /** An unobserved entry is dropped after this long. */
  gcTimeMs?: number;
  /** Whose timers (default the page's). */
  scheduler?: Scheduler;
}

const DEFAULT_GC_MS = 5 * 60_000;

export class MachineQueries implements EntryOwner, WatchedCache {
  readonly gcTimeMs: number;
  readonly scheduler: Scheduler;
  private readonly maxEntries: number;
  private readonly entries = new Map<string, Entry<unknown>>();

  constructor(
    readonly machineId: string,
    opts: MachineQueriesOptions = {},
  ) {
    this.maxEntries = opts.maxEntries ?? 200;
    this.gcTimeMs = opts.gcTimeMs ?? DEFAULT_GC_MS;
    this.scheduler = opts.scheduler ?? pageScheduler;
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
