import { useStore } from 'zustand';
import type { StoreApi } from 'zustand/vanilla';
import { describeError, LinkError } from '../../fleet/errors';
import { createSharedStore, useMachineQuery, type Fetcher, type MachineQueries } from '../../fleet/kernel';
import type { MachineSnapshot } from '../../fleet/types';
import { isUnauthorized, type TouchcutClient } from './client';
import { touchcutUnits } from './state';
import type { OpenData, Stats, UnitsChoice } from './wire';

/**
 * On-demand reads of a TouchCut machine, through the console's query layer (`ctx.queries`):
 * statistics for a range, the programs page and the part unloader. Each read is keyed under the
 * machine with everything that shapes its answer (range, page, units), so switching back to a
 * range or page shows its answer at once and refetches it only when stale; unobserved answers are
 * dropped after a while (the layer's bounded cache). A session keeps only what the user picked
 * (the range, the page), in small shared stores; views read with `useStats` / `useOpenData`.
 */

export interface ReadHost {
  client: TouchcutClient;
  queries: MachineQueries;
  snapshot: StoreApi<MachineSnapshot>;
  now: () => number;
  /** False while the machine needs a login or the session is stopped: nothing is asked. */
  canRequest: () => boolean;
  /** A 401: the session decides (needs login). */
  authFailed: (e: unknown) => void;
}

/** A read of this machine: not sent while it cannot be, and a 401 goes to the session. */
function read<T>(host: ReadHost, fn: (signal: AbortSignal) => Promise<T>): Fetcher<T> {
  return async (signal) => {
    if (!host.canRequest()) throw new LinkError('offline', 'The machine is not connected');
    try {
      return await fn(signal);
    } catch (e) {
      if (isUnauthorized(e)) host.authFailed(e);
      throw e;
    }
  };
}

interface ReadView<T> {
  data: T | null;
  /** When the shown answer arrived (ms since epoch). */
  at: number | null;
  loading: boolean;
  error: string | null;
}

function useRead<T>(
  host: ReadHost,
  key: readonly unknown[] | null,
  fn: Fetcher<T>,
  opts: { staleTimeMs: number; refetchIntervalMs?: number },
  busy: 'first' | 'any',
): ReadView<T> {
  const link = useStore(host.snapshot, (s) => s.link);
  const q = useMachineQuery(host.queries, key ?? ['none'], fn, {
    ...opts,
    enabled: key !== null && link !== 'needs-login',
  });
  return {
    data: q.data ?? null,
    at: q.updatedAt || null,
    loading: busy === 'first' ? q.loading : q.fetching,
    error: q.error ? describeError(q.error) : null,
  };
}

// ---------------------------------------------------------------------------------------------
// stats

/** Past days do not change; today's numbers do: a range shown again is read again after this. */
export const STATS_STALE_MS = 60_000;

export interface StatsRequest {
  startDate: string;
  endBeforeDate: string;
  condensed: boolean;
}

export interface StatsState extends ReadView<Stats> {
  request: StatsRequest | null;
}

export class StatsLoader {
  /** The range on screen (kept for the session: the tab shows it again when reopened). */
  readonly store = createSharedStore<{ request: StatsRequest | null }>(() => ({ request: null }));

  constructor(readonly host: ReadHost) {}

  key(req: StatsRequest, units: UnitsChoice): readonly unknown[] {
    return ['stats', req.startDate, req.endBeforeDate, req.condensed, units];
  }

  read(req: StatsRequest, units: UnitsChoice): Fetcher<Stats> {
    return read(this.host, (signal) => this.host.client.stats({ ...req, units }, signal));
  }

  /** Shows `req`; the range already shown is read again (the user asked for it). */
  load(req: StatsRequest): Promise<void> {
    const before = this.store.getState();
    this.store.setState({ request: req });
    if (this.store.getState() === before) return this.host.queries.invalidate(['stats']);
    return Promise.resolve();
  }
}

export function useStats(stats: StatsLoader): StatsState {
  const request = useStore(stats.store, (s) => s.request);
  const units = useStore(touchcutUnits, (s) => s.units);
  const view = useRead(
    stats.host,
    request && stats.key(request, units),
    request ? stats.read(request, units) : () => Promise.reject(new Error('no range')),
    { staleTimeMs: STATS_STALE_MS },
    'any',
  );
  return { ...view, request };
}

// ---------------------------------------------------------------------------------------------
// programs and unloader ("interface subject to change": generic data)

export const PROGRAMS_REFRESH_MS = 5000;

export interface OpenDataParams {
  offset: number;
  limit: number;
  history: { startDate: string; endBeforeDate: string } | null;
}

export type OpenDataState = ReadView<OpenData> & OpenDataParams;

/** Deeper than this a changed object replaces the page's whole (a page is never this deep). */
const MERGE_DEPTH = 64;

function isRecord(v: unknown): v is Record<string, unknown> {
  return typeof v === 'object' && v !== null && !Array.isArray(v);
}

/**
 * Deep merge for `onlyChangedData` refreshes: objects merge key by key, arrays and values replace.
 * The answer is untrusted: own keys only, each kept as data (`__proto__` too: never a prototype),
 * and the walk stops at MERGE_DEPTH (never past the stack).
 */
export function mergeChanged(base: unknown, changed: unknown, depth = 0): unknown {
  if (!isRecord(base) || !isRecord(changed) || depth >= MERGE_DEPTH) return changed;
  const out: Record<string, unknown> = {};
  const put = (k: string, v: unknown) =>
    Object.defineProperty(out, k, { value: v, enumerable: true, writable: true, configurable: true });
  for (const [k, v] of Object.entries(base)) put(k, v);
  for (const [k, v] of Object.entries(changed))
    put(k, mergeChanged(Object.hasOwn(base, k) ? base[k] : undefined, v, depth + 1));
  return out;
}

/**
 * `rest/v1/programs` (pages of `offset`/`limit`) or `rest/v1/unloader` (with a history range),
 * refreshed every 5 s while on screen. A programs refresh of the page just read asks only for
 * changed data (`onlyChangedData`) and merges it in; a first read, a new page or Reload asks for all.
 */
export class OpenDataFeed {
  readonly store = createSharedStore<OpenDataParams>(() => ({ offset: 0, limit: 25, history: null }));
  /** Reload: the next read asks for everything. */
  private full = false;

  constructor(
    readonly host: ReadHost,
    readonly kind: 'programs' | 'unloader',
  ) {}

  key(p: OpenDataParams, units: UnitsChoice): readonly unknown[] {
    return this.kind === 'programs'
      ? ['programs', p.offset, p.limit, units]
      : ['unloader', p.history?.startDate ?? null, p.history?.endBeforeDate ?? null, units];
  }

  read(p: OpenDataParams, units: UnitsChoice): Fetcher<OpenData> {
    const { client } = this.host;
    if (this.kind === 'unloader') {
      const h = p.history;
      return read(this.host, (signal) =>
        client.unloader(
          { history: h !== null, startDate: h?.startDate, endBeforeDate: h?.endBeforeDate, units },
          signal,
        ),
      );
    }
    return read(this.host, async (signal) => {
      const base = this.recent(this.key(p, units));
      const onlyChangedData = base !== undefined;
      const data = await client.programs(
        { offset: p.offset, limit: p.limit, onlyChangedData, units },
        signal,
      );
      return base === undefined ? data : (mergeChanged(base, data) as OpenData);
    });
  }

  /** The answer to refresh with changed data only: this page's, read within the last two refreshes. */
  private recent(key: readonly unknown[]): OpenData | undefined {
    if (this.full) {
      this.full = false;
      return undefined;
    }
    const s = this.host.queries.cached<OpenData>(key);
    if (!s) return undefined;
    return this.host.now() - s.updatedAt <= 2 * PROGRAMS_REFRESH_MS ? s.data : undefined;
  }

  page(offset: number, limit: number): void {
    this.store.setState({ offset: Math.max(0, offset), limit });
  }

  setHistory(h: { startDate: string; endBeforeDate: string } | null): void {
    this.store.setState({ history: h });
  }

  reload(): void {
    this.full = true;
    void this.host.queries.invalidate([this.kind]);
  }
}

export function useOpenData(feed: OpenDataFeed): OpenDataState {
  const params = useStore(feed.store);
  const units = useStore(touchcutUnits, (s) => s.units);
  const view = useRead(
    feed.host,
    feed.key(params, units),
    feed.read(params, units),
    { staleTimeMs: PROGRAMS_REFRESH_MS, refetchIntervalMs: PROGRAMS_REFRESH_MS },
    'first',
  );
  return { ...view, ...params };
}
