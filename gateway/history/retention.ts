import type { Logger } from '../log';
import type { Retention } from '../settings';
import type { Db } from './db';
import { localDay } from './shifts';

/** The history's retention: what is older than the settings keep is deleted, a batch at a time. */

const PRUNE_BATCH = 5000;
const DAY_MS = 86_400_000;

export interface PruneCounts {
  jobs: number;
  states: number;
  touchcutDays: number;
}

export interface PruneOptions {
  db: Db;
  log: Logger;
  now: () => number;
  /** Read when pruning starts. */
  retention: () => Retention;
  /** The store was closed meanwhile: stop. */
  isClosed: () => boolean;
}

function* pruneBatched(o: PruneOptions, sql: string, param: number | string): Generator<void, number> {
  let total = 0;
  for (;;) {
    if (o.isClosed()) return total;
    const n = o.db.prepare(sql).run(param, PRUNE_BATCH).changes;
    total += n;
    if (n < PRUNE_BATCH) return total;
    yield;
  }
}

/**
 * Deletes ended jobs and TouchCut days older than `jobsDays`, state intervals that ended more than
 * `statesDays` ago (open ones never), then the last-seen times of machines with no record left;
 * yields after each batch of `PRUNE_BATCH` rows.
 */
export function* pruneSteps(o: PruneOptions): Generator<void, PruneCounts> {
  if (o.isClosed()) return { jobs: 0, states: 0, touchcutDays: 0 };
  const r = o.retention();
  const t = o.now();
  const jobsCut = t - r.jobsDays * DAY_MS;
  const statesCut = t - r.statesDays * DAY_MS;
  const jobs = yield* pruneBatched(
    o,
    'DELETE FROM jobs WHERE id IN (SELECT id FROM jobs WHERE ended_at IS NOT NULL AND ended_at < ? LIMIT ?)',
    jobsCut,
  );
  const states = yield* pruneBatched(
    o,
    'DELETE FROM states WHERE id IN (SELECT id FROM states WHERE ended_at IS NOT NULL AND ended_at < ? LIMIT ?)',
    statesCut,
  );
  if (o.isClosed()) return { jobs, states, touchcutDays: 0 };
  const touchcutDays = o.db.prepare('DELETE FROM touchcut_days WHERE day < ?').run(localDay(jobsCut)).changes;
  // A machine with no record left is forgotten (the machine lists of the API).
  o.db.exec(`DELETE FROM last_seen WHERE
    NOT EXISTS (SELECT 1 FROM states s WHERE s.machine = last_seen.machine) AND
    NOT EXISTS (SELECT 1 FROM jobs j WHERE j.machine = last_seen.machine)`);
  if (jobs || states || touchcutDays)
    o.log.info('history pruned', { jobs, states, touchcutDays, retention: r });
  return { jobs, states, touchcutDays };
}
