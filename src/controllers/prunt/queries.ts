import type { PruntApi } from './config-ir';

/**
 * On-demand reads of a Prunt machine, through the machine's query layer (`ctx.queries`, keys
 * under the machine id, cancelled and dropped on stop, bounded cache). The live status is the
 * socket's, not a query.
 *
 * - `files`: the uploads list, fresh for `FILES_STALE_MS`; an upload invalidates it.
 * - `statusSchema`, `updateCheck`: read on connect and after a server restart (never cached
 *   across those: stale at once, but one request at a time).
 * - `configSchema`, `configValues`: read when the editor opens, on "Reload" and after a server
 *   restart — never polled, never invalidated by the query layer (no observer, no command
 *   declares them). A plain read (not audited); a save's reply carries the new values.
 */
export const PRUNT_KEYS = {
  files: ['files'],
  statusSchema: ['status', 'schema'],
  updateCheck: (api: PruntApi) => ['update-check', api],
  configSchema: ['config', 'schema'],
  configValues: ['config', 'values'],
} as const;

export const FILES_STALE_MS = 10_000;

/** Reads that must be fresh each time they are asked for (one in flight at a time). */
export const ALWAYS_FRESH = { staleTimeMs: 0 } as const;
