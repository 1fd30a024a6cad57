import type { WatchSummary } from '../../src/fleet/contract';
import type { HistoryDays } from '../../src/fleet/server-part';
import type { Logger } from '../log';
import { DEFAULT_RETENTION, type Retention } from '../settings';
import { openHistoryDb, type Db, type Migration, MIGRATIONS } from './db';
import type {
  HistoryInfo,
  HistoryMachine,
  Interval,
  JobCommand,
  JobCounts,
  JobQuery,
  JobRow,
  RangeQuery,
  StateSeconds,
  StopReason,
  TouchcutDay,
} from './model';
import { HistoryReader, type LiveJob as LiveJobView } from './reader';
import { HistoryRecorder } from './recorder';
import { pruneSteps, type PruneCounts } from './retention';

/**
 * The production history: every job and state change of every machine, recorded from the
 * gateway's watch (watch.ts) whether or not a page is open, and TouchCut's daily statistics, in
 * one SQLite file (db.ts). The parts: recorder.ts (recording), reader.ts (queries),
 * retention.ts (pruning), model.ts (the shapes).
 */

export { HEARTBEAT_MS, SEEN_EVERY_MS, CHECKPOINT_EVERY_MS, START_WINDOW_MS, LATE_STOP_MS } from './recorder';
export * from './model';

export interface HistoryStoreOptions {
  file: string;
  log: Logger;
  now?: () => number;
  retention?: () => Retention;
  /** Tests: open with fewer migrations (an older version of the file). */
  migrations?: readonly Migration[];
  /** The job commands by what they do (`jobCommandsOf(families)`). */
  jobCommands: Readonly<Record<string, JobCommand>>;
}

export class HistoryStore {
  readonly db: Db;
  readonly file: string;
  private readonly now: () => number;
  private readonly retention: () => Retention;
  private closed = false;
  /** The recording (recorder.ts), on this connection. */
  private readonly recorder: HistoryRecorder;
  /** What `recover()` closed when the store opened. */
  readonly recovered: { jobs: number; states: number };
  readonly applied: string[];
  /** The queries (reader.ts), on this connection. */
  readonly reader: HistoryReader;

  constructor(private readonly opts: HistoryStoreOptions) {
    this.file = opts.file;
    this.now = opts.now ?? Date.now;
    this.retention = opts.retention ?? (() => DEFAULT_RETENTION);
    const { db, applied } = openHistoryDb(opts.file, opts.migrations ?? MIGRATIONS);
    this.db = db;
    this.applied = applied;
    if (applied.length) opts.log.info('history database migrated', { file: opts.file, applied });
    this.reader = new HistoryReader({
      db,
      file: opts.file,
      now: this.now,
      retention: this.retention,
      live: (machine) => this.liveJob(machine),
    });
    this.recorder = new HistoryRecorder({
      db,
      log: opts.log,
      now: this.now,
      jobCommands: opts.jobCommands,
      isClosed: () => this.closed,
    });
    this.recovered = this.recorder.recovered;
  }

  // ------------------------------------------------------------------------------ recording (recorder.ts)

  /** What the watch learnt about a machine (every summary, with the one before). */
  observe(m: HistoryMachine, prev: WatchSummary, next: WatchSummary): void {
    this.recorder.observe(m, prev, next);
  }

  /** A command the gateway forwarded to a machine and the machine accepted (from the audit record). */
  command(machine: string, commandId: string | undefined, user: string): void {
    this.recorder.command(machine, commandId, user);
  }

  /** Every `HEARTBEAT_MS`: last-seen times and open jobs' counted time; a checkpoint each minute. */
  heartbeat(): void {
    this.recorder.heartbeat();
  }

  // ------------------------------------------------------------------------------ retention (retention.ts)

  /** Deletes what is older than the retention (jobs and TouchCut days: `jobsDays`; states: `statesDays`). */
  prune(): PruneCounts {
    const steps = this.pruneSteps();
    for (;;) {
      const s = steps.next();
      if (s.done) return s.value;
    }
  }

  /**
   * `prune()` a batch at a time, letting the gateway's other work in between (a shorter retention
   * can delete hundreds of thousands of rows: done in one go it would hold the thread for seconds).
   */
  async pruneGently(): Promise<PruneCounts> {
    const steps = this.pruneSteps();
    for (;;) {
      const s = steps.next();
      if (s.done) return s.value;
      await new Promise((r) => setImmediate(r));
    }
  }

  private pruneSteps(): Generator<void, PruneCounts> {
    return pruneSteps({
      db: this.db,
      log: this.opts.log,
      now: this.now,
      retention: this.retention,
      isClosed: () => this.closed,
    });
  }

  /** Writes the last-seen times and closes the file (the gateway stops). */
  close(): void {
    if (this.closed) return;
    this.heartbeat();
    this.closed = true;
    try {
      this.db.pragma('wal_checkpoint(TRUNCATE)');
    } catch {
      /* a reader holds it: the WAL stays, which is fine */
    }
    this.db.close();
  }

  get isClosed(): boolean {
    return this.closed;
  }

  /** The days of statistics a controller keeps itself (`touchcut_days`), for a family's puller. */
  statsDays(): HistoryDays {
    const closed = (): boolean => this.closed;
    return {
      get isClosed() {
        return closed();
      },
      held: (machine, fromDay) => this.touchcutDaysHeld(machine, fromDay),
      put: (machine, day, stats, pulledAt) => this.putTouchcutDay(machine, day, stats, pulledAt),
    };
  }

  // ------------------------------------------------------------------------------ TouchCut

  putTouchcutDay(machine: string, day: string, stats: unknown, pulledAt: number): void {
    this.db
      .prepare(
        `INSERT INTO touchcut_days (machine, day, pulled_at, stats) VALUES (?, ?, ?, ?)
         ON CONFLICT (machine, day) DO UPDATE SET pulled_at = excluded.pulled_at, stats = excluded.stats`,
      )
      .run(machine, day, pulledAt, JSON.stringify(stats));
  }

  touchcutDaysHeld(machine: string, fromDay: string): Set<string> {
    const rows = this.db
      .prepare('SELECT day FROM touchcut_days WHERE machine = ? AND day >= ?')
      .pluck()
      .all(machine, fromDay) as string[];
    return new Set(rows);
  }

  // ------------------------------------------------------------------------------ queries (reader.ts)

  /** A machine's open job as counted in memory (the queries count it up to now). */
  liveJob(machine: string): LiveJobView | undefined {
    return this.recorder.liveJob(machine);
  }

  /** Every open job as counted in memory, by machine: what a read worker needs to count them. */
  liveJobs(): Record<string, LiveJobView> {
    return this.recorder.liveJobs();
  }

  touchcutDays(q: Parameters<HistoryReader['touchcutDays']>[0]): TouchcutDay[] {
    return this.reader.touchcutDays(q);
  }

  jobs(q: JobQuery): { jobs: JobRow[]; total: number } {
    return this.reader.jobs(q);
  }

  states(q: RangeQuery, max?: number): { intervals: Interval[]; truncated: boolean } {
    return this.reader.states(q, max);
  }

  utilisation(q: RangeQuery): Map<string, StateSeconds> {
    return this.reader.utilisation(q);
  }

  stops(q: RangeQuery, limit?: number): StopReason[] {
    return this.reader.stops(q, limit);
  }

  jobCounts(q: RangeQuery): Map<string, JobCounts> {
    return this.reader.jobCounts(q);
  }

  machinesRecorded(): string[] {
    return this.reader.machinesRecorded();
  }

  sizeBytes(): number {
    return this.reader.sizeBytes();
  }

  info(): HistoryInfo {
    return this.reader.info();
  }
}
