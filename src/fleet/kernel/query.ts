import { QueryClient, QueryObserver, type QueryKey, type QueryObserverResult } from '@tanstack/query-core';
import { useCallback, useEffect, useState, useSyncExternalStore } from 'react';

/**
 * On-demand reads (files, file info, settings, stats, programs, thumbnails) go through one
 * query layer per machine: keyed under the machine's id, with stale times, no two requests for
 * the same key at once, invalidation after a command, cancellation on stop (the request's
 * AbortSignal), and a bounded cache (least recently used unobserved entries go first, and any
 * unobserved entry after `gcTimeMs`). The live link (polls, sockets) stays the session's.
 */

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

export class MachineQueries {
  readonly client: QueryClient;
  private readonly maxEntries: number;

  constructor(
    readonly machineId: string,
    opts: MachineQueriesOptions = {},
  ) {
    this.maxEntries = opts.maxEntries ?? 200;
    this.client = new QueryClient({
      defaultOptions: {
        queries: {
          gcTime: opts.gcTimeMs ?? 5 * 60_000,
          staleTime: 10_000,
          // The console says what failed and offers a retry; nothing retried behind the user's back.
          retry: false,
          refetchOnWindowFocus: false,
          refetchOnReconnect: false,
          networkMode: 'always',
        },
      },
    });
    this.client.mount();
    this.client.getQueryCache().subscribe((ev) => {
      if (ev.type === 'added') this.trim();
    });
  }

  /** The full key of a read of this machine. */
  key(...parts: readonly unknown[]): QueryKey {
    return [this.machineId, ...parts];
  }

  /** One read (deduplicated with any in flight; cached for `staleTimeMs`). */
  fetch<T>(parts: readonly unknown[], fn: Fetcher<T>, opts: QueryOptions = {}): Promise<T> {
    return this.client.fetchQuery({
      queryKey: this.key(...parts),
      queryFn: ({ signal }) => fn(signal),
      staleTime: opts.staleTimeMs,
    });
  }

  /** The cached answer, if any (no request). */
  peek<T>(parts: readonly unknown[]): T | undefined {
    return this.client.getQueryData<T>(this.key(...parts));
  }

  /** Marks every read under `parts` stale and refetches those on screen. */
  invalidate(parts: readonly unknown[] = []): Promise<void> {
    return this.client.invalidateQueries({ queryKey: this.key(...parts) });
  }

  /** Drops everything (the session stopped): in-flight reads are cancelled. */
  clear(): void {
    void this.client.cancelQueries();
    this.client.clear();
  }

  /** Number of cached entries, for tests. */
  get size(): number {
    return this.client.getQueryCache().getAll().length;
  }

  private trim(): void {
    const cache = this.client.getQueryCache();
    const all = cache.getAll();
    if (all.length <= this.maxEntries) return;
    const idle = all
      .filter(
        // Never the entry being added or read (no answer yet), never one on screen.
        (q) =>
          q.getObserversCount() === 0 && q.state.status !== 'pending' && q.state.fetchStatus !== 'fetching',
      )
      .sort((a, b) => a.state.dataUpdatedAt - b.state.dataUpdatedAt);
    for (const q of idle.slice(0, all.length - this.maxEntries)) cache.remove(q);
  }
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

/** A React view of one read of a machine: shown from cache at once, refetched when stale. */
export function useMachineQuery<T>(
  queries: MachineQueries,
  parts: readonly unknown[],
  fn: Fetcher<T>,
  opts: QueryOptions = {},
): QueryView<T> {
  const options = {
    queryKey: queries.key(...parts),
    queryFn: ({ signal }: { signal: AbortSignal }) => fn(signal),
    staleTime: opts.staleTimeMs,
    enabled: opts.enabled ?? true,
    refetchInterval: opts.refetchIntervalMs ?? false,
  } as const;
  const [observer] = useState(() => new QueryObserver<T, Error>(queries.client, options));
  useEffect(() => {
    observer.setOptions(options);
  });
  const subscribe = useCallback((onChange: () => void) => observer.subscribe(() => onChange()), [observer]);
  const result: QueryObserverResult<T, Error> = useSyncExternalStore(
    subscribe,
    () => observer.getCurrentResult(),
    () => observer.getCurrentResult(),
  );
  return {
    data: result.data,
    error: result.error,
    loading: result.isPending && result.fetchStatus === 'fetching',
    fetching: result.fetchStatus === 'fetching',
    updatedAt: result.dataUpdatedAt,
    refetch: () => void observer.refetch(),
  };
}
