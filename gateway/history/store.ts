import type Database from 'better-sqlite3';
import type { JobCommandIds, WatchSummary } from '../../src/fleet/contract';
import type { HistoryDays } from '../../src/fleet/server-part';
import type { Logger } from '../log';
import { DEFAULT_RETENTION, type Retention } from '../settings';
import { openHistoryDb, type Db, type Migration, MIGRATIONS } from './db';
import { HistoryReader, type LiveJob as LiveJobView } from './reader';
import { localDay } from './shifts';

/**
 * The production history: every job and every state change of every machine, recorded from the
 * gateway's watch (watch.ts) whether or not a page is open, and TouchCut's daily statistics. One
 * SQLite file (db.ts); each change is one transaction.
 *
 * Jobs. A job opens when a machine goes to `running` or `paused` with no job open, and ends:
 * - `cancelled`: it went to `idle` after a stop command from the console (`jobCommands`) during
 *   the job, or a stop command came within `LATE_STOP_MS` after it went idle (the watch can see
 *   the machine stop before the gateway has the command's answer);
 * - `failed`: it went to `alarm` (the alarm's text is kept as `end_alarm`);
 * - `finished`: it went to `idle` straight from `running` or `paused`;
 * - `unknown`: it went to `idle` after the console lost sight of the machine (`offline`/`unknown`
 *   during the job), the machine named another job while one was open, or the console stopped
 *   while it ran (closed at the machine's last-seen time when the console starts again).
 * A job stays open while the machine is `offline` or `unknown`; that time counts neither as
 * running nor as paused. Who started, paused, resumed and stopped it comes from the commands the
 * gateway forwarded for the machine (the last of each kind; a start within `START_WINDOW_MS`
 * before the job opened, or just after).
 *
 * State intervals. Each change of state or alarm text closes the machine's open interval and
 * opens the next, so the time in each state sums for any range. A heartbeat every
 * `HEARTBEAT_MS` stores each machine's last-seen time (and an open job's running and paused
 * time), so after a stop or a crash the console closes open jobs and intervals there.
 */

export const STATES = ['running', 'paused', 'idle', 'alarm', 'offline', 'unknown'] as const;
export type HistoryState = (typeof STATES)[number];
export const OUTCOMES = ['finished', 'cancelled', 'failed', 'unknown'] as const;
export type Outcome = (typeof OUTCOMES)[number];

export type JobCommand = 'start' | 'pause' | 'resume' | 'stop';

/**
 * The console's job commands (the `X-Shopdeck-Command` ids the families send) by what they do,
 * from each family's `jobs` declaration (`FamilyDeclaration.jobs`): its emergency stop also
 * stops the job.
 */
export function jobCommandsOf(
  families: Partial<Record<string, { jobs?: JobCommandIds }>>,
): Readonly<Record<string, JobCommand>> {
  const out: Record<string, JobCommand> = {};
  for (const f of Object.values(families)) {
    const j = f?.jobs;
    if (!j) continue;
    if (j.start) out[j.start] = 'start';
    out[j.pause] = 'pause';
    out[j.resume] = 'resume';
    out[j.stop] = 'stop';
    if (j.estop) out[j.estop] = 'stop';
  }
  return out;
}

export const HEARTBEAT_MS = 5000;
/** A summary with no change refreshes the last-seen time at most this often. */
export const SEEN_EVERY_MS = 5000;
export const CHECKPOINT_EVERY_MS = 60_000;
/** A start command this long before a job opens (or after: the watch may see it first) started it. */
export const START_WINDOW_MS = 5 * 60_000;
export const LATE_STOP_MS = 30_000;
const MAX_TEXT = 500;
const MAX_USER = 200;
const PRUNE_BATCH = 5000;
const DAY_MS = 86_400_000;

export interface HistoryMachine {
  id: string;
  name: string;
  kind: string;
}

export interface JobRow {
  id: number;
  machine: string;
  family: string;
  name: string | null;
  /** ms since the epoch */
  startedAt: number;
  endedAt: number | null;
  /** null: still open */
  outcome: Outcome | null;
  runningMs: number;
  pausedMs: number;
  progress: number | null;
  startedBy: string | null;
  pausedBy: string | null;
  resumedBy: string | null;
  stoppedBy: string | null;
  endAlarm: string | null;
}

export interface Interval {
  machine: string;
  state: HistoryState;
  alarm: string | null;
  /** Clipped to the range asked for. */
  from: number;
  to: number;
  /** Still open (its end is "now"). */
  open: boolean;
}

export type StateSeconds = Record<HistoryState | 'unrecorded', number>;

export interface JobQuery {
  /** The machines the asker may see (null: all). */
  machines: readonly string[] | null;
  machine?: string;
  family?: string;
  outcome?: Outcome | 'open';
  /** Jobs that overlap [from, to). */
  from?: number;
  to?: number;
  /** Text in the job's name or in a user's name (case-insensitive). */
  q?: string;
  limit?: number;
  offset?: number;
}

export interface RangeQuery {
  machines: readonly string[] | null;
  machine?: string;
  from: number;
  to: number;
}

export interface StopReason {
  alarm: string | null;
  count: number;
  ms: number;
  machines: string[];
}

export interface JobCounts {
  finished: number;
  cancelled: number;
  failed: number;
  unknown: number;
  /** Overlapping the range and not ended in it (ended later, or still open). */
  inProgress: number;
}

export interface TouchcutDay {
  machine: string;
  day: string;
  pulledAt: number;
  stats: unknown;
}

export interface HistoryInfo {
  file: string;
  /** The database file with its write-ahead log. */
  sizeBytes: number;
  schemaVersion: number;
  oldest: { job: number | null; state: number | null; touchcutDay: string | null };
  counts: { jobs: number; states: number; touchcutDays: number };
  retention: Retention;
}

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

interface LiveJob {
  id: number;
  name: string | null;
  startedAt: number;
  countedTo: number;
  runningMs: number;
  pausedMs: number;
  progress: number | null;
  startedBy: string | null;
  stopAsked: boolean;
  /** The console lost sight of the machine during the job. */
  blind: boolean;
}

interface Live {
  kind: string;
  intervalId: number;
  state: HistoryState;
  alarm: string | null;
  since: number;
  job: LiveJob | null;
  seenWritten: number;
  lastClosed: { id: number; endedAt: number; outcome: Outcome } | null;
}

function clip(text: string | null | undefined, max = MAX_TEXT): string | null {
  if (text === null || text === undefined) return null;
  const t = text.trim();
  return t ? t.slice(0, max) : null;
}

function isJobState(s: HistoryState): boolean {
  return s === 'running' || s === 'paused';
}

export class HistoryStore {
  readonly db: Db;
  readonly file: string;
  private readonly now: () => number;
  private readonly retention: () => Retention;
  private readonly live = new Map<string, Live>();
  private readonly pendingStarts = new Map<string, { user: string; at: number }>();
  private lastCheckpoint: number;
  private lastError = 0;
  private closed = false;
  /** What `recover()` closed when the store opened. */
  readonly recovered: { jobs: number; states: number };
  readonly applied: string[];
  /** The queries (reader.ts), on this connection. */
  readonly reader: HistoryReader;

  private readonly st: {
    openInterval: Database.Statement;
    closeInterval: Database.Statement;
    openJob: Database.Statement;
    countJob: Database.Statement;
    closeJob: Database.Statement;
    seen: Database.Statement;
  };

  constructor(private readonly opts: HistoryStoreOptions) {
    this.file = opts.file;
    this.now = opts.now ?? Date.now;
    this.retention = opts.retention ?? (() => DEFAULT_RETENTION);
    const { db, applied } = openHistoryDb(opts.file, opts.migrations ?? MIGRATIONS);
    this.db = db;
    this.applied = applied;
    if (applied.length) opts.log.info('history database migrated', { file: opts.file, applied });
    this.lastCheckpoint = this.now();
    this.reader = new HistoryReader({
      db,
      file: opts.file,
      now: this.now,
      retention: this.retention,
      live: (machine) => this.liveJob(machine),
    });
    this.st = {
      openInterval: db.prepare(
        'INSERT INTO states (machine, state, alarm, started_at, ended_at) VALUES (?, ?, ?, ?, NULL)',
      ),
      closeInterval: db.prepare('UPDATE states SET ended_at = ? WHERE id = ?'),
      openJob: db.prepare(
        'INSERT INTO jobs (machine, family, name, started_at, counted_to, started_by) VALUES (?, ?, ?, ?, ?, ?)',
      ),
      countJob: db.prepare(
        'UPDATE jobs SET running_ms = ?, paused_ms = ?, counted_to = ?, progress = ?, name = ? WHERE id = ?',
      ),
      closeJob: db.prepare(
        `UPDATE jobs SET running_ms = ?, paused_ms = ?, counted_to = ?, progress = ?, name = ?,
           ended_at = ?, outcome = ?, end_alarm = ? WHERE id = ?`,
      ),
      seen: db.prepare(
        'INSERT INTO last_seen (machine, at) VALUES (?, ?) ON CONFLICT (machine) DO UPDATE SET at = excluded.at',
      ),
    };
    this.recovered = this.recover();
    if (this.recovered.jobs || this.recovered.states)
      opts.log.info(
        'history: closed what was open when the console stopped, at the last time it saw each machine',
        {
          jobs: this.recovered.jobs,
          states: this.recovered.states,
        },
      );
  }

  // ------------------------------------------------------------------------------ recording

  /**
   * The console (re)started: every job still open is closed as `unknown` and every open state
   * interval is closed, each at its machine's last-seen time (the job's counted time ends there).
   */
  private recover(): { jobs: number; states: number } {
    return this.db
      .transaction(() => {
        const seen = '(SELECT at FROM last_seen l WHERE l.machine = %s.machine)';
        const jobs = this.db
          .prepare(
            `UPDATE jobs SET outcome = 'unknown',
               ended_at = MAX(started_at, counted_to, COALESCE(${seen.replace('%s', 'jobs')}, 0))
             WHERE ended_at IS NULL`,
          )
          .run().changes;
        const states = this.db
          .prepare(
            `UPDATE states SET ended_at = MAX(started_at, COALESCE(${seen.replace('%s', 'states')}, 0))
             WHERE ended_at IS NULL`,
          )
          .run().changes;
        return { jobs, states };
      })
      .immediate();
  }

  /** Runs `f` in a transaction; on failure the machine's in-memory state is put back and it is logged. */
  private guarded(machine: string, what: string, f: () => void): void {
    if (this.closed) return;
    const before = this.live.get(machine);
    const copy = before ? structuredClone(before) : undefined;
    try {
      this.db.transaction(f).immediate();
    } catch (e) {
      if (copy) this.live.set(machine, copy);
      else this.live.delete(machine);
      const t = this.now();
      if (t - this.lastError > 60_000) {
        this.lastError = t;
        this.opts.log.error(`history: could not record ${what}`, { machine, error: String(e) });
      }
    }
  }

  /** Adds the time since the job was last counted to running or paused, by the state it was in. */
  private count(live: Live, t: number): void {
    const job = live.job;
    if (!job) return;
    const d = Math.max(0, t - job.countedTo);
    if (live.state === 'running') job.runningMs += d;
    else if (live.state === 'paused') job.pausedMs += d;
    job.countedTo = Math.max(job.countedTo, t);
  }

  private writeJob(job: LiveJob): void {
    this.st.countJob.run(job.runningMs, job.pausedMs, job.countedTo, job.progress, job.name, job.id);
  }

  private closeJob(live: Live, t: number, outcome: Outcome, endAlarm: string | null): void {
    const job = live.job;
    if (!job) return;
    this.st.closeJob.run(
      job.runningMs,
      job.pausedMs,
      job.countedTo,
      job.progress,
      job.name,
      t,
      outcome,
      endAlarm,
      job.id,
    );
    live.lastClosed = { id: job.id, endedAt: t, outcome };
    live.job = null;
  }

  private openJob(m: HistoryMachine, live: Live, t: number, name: string | null): void {
    const pending = this.pendingStarts.get(m.id);
    const startedBy = pending && t - pending.at <= START_WINDOW_MS ? pending.user : null;
    this.pendingStarts.delete(m.id);
    const id = Number(this.st.openJob.run(m.id, m.kind, name, t, t, startedBy).lastInsertRowid);
    live.job = {
      id,
      name,
      startedAt: t,
      countedTo: t,
      runningMs: 0,
      pausedMs: 0,
      progress: null,
      startedBy,
      stopAsked: false,
      blind: false,
    };
  }

  /** What the watch learnt about a machine (every summary, with the one before). */
  observe(m: HistoryMachine, _prev: WatchSummary, next: WatchSummary): void {
    if (this.closed) return;
    const state: HistoryState = STATES.includes(next.state) ? next.state : 'unknown';
    const alarm = clip(next.alarm);
    const name = clip(next.job);
    const progress =
      typeof next.progress === 'number' && Number.isFinite(next.progress)
        ? Math.min(1, Math.max(0, next.progress))
        : null;
    // Nothing to write (a stream's frames come often): the progress is kept in memory only.
    const known = this.live.get(m.id);
    const job0 = known?.job;
    if (
      known &&
      state === known.state &&
      alarm === known.alarm &&
      !(job0 && name && (job0.name === null || (name !== job0.name && isJobState(state)))) &&
      this.now() - known.seenWritten < SEEN_EVERY_MS
    ) {
      if (job0 && progress !== null) job0.progress = progress;
      return;
    }
    this.guarded(m.id, 'a state change', () => {
      let live = this.live.get(m.id);
      // The clock never runs backwards inside a machine's record (a clock set back by hand).
      const t = Math.max(this.now(), live?.since ?? 0, live?.job?.countedTo ?? 0);
      let changed = false;
      let stateChanged = false;
      const was = live?.state ?? 'unknown';
      if (!live) {
        const intervalId = Number(this.st.openInterval.run(m.id, state, alarm, t).lastInsertRowid);
        live = {
          kind: m.kind,
          intervalId,
          state,
          alarm,
          since: t,
          job: null,
          seenWritten: 0,
          lastClosed: null,
        };
        this.live.set(m.id, live);
        changed = true;
        stateChanged = true;
      } else if (state !== live.state || alarm !== live.alarm) {
        this.count(live, t);
        this.st.closeInterval.run(t, live.intervalId);
        live.intervalId = Number(this.st.openInterval.run(m.id, state, alarm, t).lastInsertRowid);
        stateChanged = state !== live.state;
        live.state = state;
        live.alarm = alarm;
        live.since = t;
        changed = true;
      }
      // The summary that ends a job may still say how far it got (TouchCut at 100 %).
      if (live.job && progress !== null) live.job.progress = progress;
      if (stateChanged) {
        const open = live.job;
        if (isJobState(state)) {
          if (!open) this.openJob(m, live, t, name);
        } else if (open && state === 'idle') {
          const outcome: Outcome = open.stopAsked
            ? 'cancelled'
            : isJobState(was) && !open.blind
              ? 'finished'
              : 'unknown';
          this.closeJob(live, t, outcome, null);
        } else if (open && state === 'alarm') {
          this.closeJob(live, t, 'failed', alarm);
        } else if (open) {
          open.blind = true; // offline or unknown: the job stays open
        }
      }
      const job = live.job;
      if (job && name && job.name && name !== job.name && isJobState(state)) {
        // Another job while one was open: the watch missed the end of the first.
        this.count(live, t);
        this.closeJob(live, t, 'unknown', null);
        this.openJob(m, live, t, name);
        changed = true;
      } else if (job && !job.name && name) {
        job.name = name;
        changed = true;
      }
      if (live.job && progress !== null) live.job.progress = progress;
      if (changed && live.job) this.writeJob(live.job);
      if (changed || t - live.seenWritten >= SEEN_EVERY_MS) {
        this.st.seen.run(m.id, t);
        live.seenWritten = t;
      }
    });
  }

  /** A command the gateway forwarded to a machine and the machine accepted (from the audit record). */
  command(machine: string, commandId: string | undefined, user: string): void {
    const kind = commandId ? this.opts.jobCommands[commandId] : undefined;
    if (!kind) return;
    const who = clip(user, MAX_USER) ?? 'unknown';
    this.guarded(machine, 'a job command', () => {
      const t = this.now();
      const live = this.live.get(machine);
      const job = live?.job ?? null;
      const set = (col: 'started_by' | 'paused_by' | 'resumed_by' | 'stopped_by', id: number): void => {
        this.db.prepare(`UPDATE jobs SET ${col} = ? WHERE id = ?`).run(who, id);
      };
      switch (kind) {
        case 'start':
          if (job && !job.startedBy && t - job.startedAt <= START_WINDOW_MS) {
            job.startedBy = who;
            set('started_by', job.id);
          } else this.pendingStarts.set(machine, { user: who, at: t });
          return;
        case 'pause':
          if (job) set('paused_by', job.id);
          return;
        case 'resume':
          if (job) set('resumed_by', job.id);
          return;
        case 'stop': {
          if (job) {
            job.stopAsked = true;
            set('stopped_by', job.id);
            return;
          }
          const last = live?.lastClosed;
          if (last && last.outcome === 'finished' && t - last.endedAt <= LATE_STOP_MS) {
            this.db
              .prepare("UPDATE jobs SET outcome = 'cancelled', stopped_by = ? WHERE id = ?")
              .run(who, last.id);
            last.outcome = 'cancelled';
          }
          return;
        }
      }
    });
  }

  /** Every `HEARTBEAT_MS`: last-seen times and open jobs' counted time; a checkpoint each minute. */
  heartbeat(): void {
    if (this.closed) return;
    const t0 = this.now();
    try {
      this.db
        .transaction(() => {
          for (const [machine, live] of this.live) {
            const t = Math.max(t0, live.since);
            if (live.job) {
              this.count(live, t);
              this.writeJob(live.job);
            }
            this.st.seen.run(machine, t);
            live.seenWritten = t;
          }
        })
        .immediate();
      if (t0 - this.lastCheckpoint >= CHECKPOINT_EVERY_MS) {
        this.lastCheckpoint = t0;
        this.db.pragma('wal_checkpoint(PASSIVE)');
      }
    } catch (e) {
      if (t0 - this.lastError > 60_000) {
        this.lastError = t0;
        this.opts.log.error('history: could not record the last-seen times', { error: String(e) });
      }
    }
  }

  /** Deletes what is older than the retention (jobs and TouchCut days: `jobsDays`; states: `statesDays`). */
  prune(): { jobs: number; states: number; touchcutDays: number } {
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
  async pruneGently(): Promise<{ jobs: number; states: number; touchcutDays: number }> {
    const steps = this.pruneSteps();
    for (;;) {
      const s = steps.next();
      if (s.done) return s.value;
      await new Promise((r) => setImmediate(r));
    }
  }

  private *pruneBatched(sql: string, param: number | string): Generator<void, number> {
    let total = 0;
    for (;;) {
      if (this.closed) return total;
      const n = this.db.prepare(sql).run(param, PRUNE_BATCH).changes;
      total += n;
      if (n < PRUNE_BATCH) return total;
      yield;
    }
  }

  /** The pruning, yielding after each batch of `PRUNE_BATCH` rows. */
  private *pruneSteps(): Generator<void, { jobs: number; states: number; touchcutDays: number }> {
    if (this.closed) return { jobs: 0, states: 0, touchcutDays: 0 };
    const r = this.retention();
    const t = this.now();
    const jobsCut = t - r.jobsDays * DAY_MS;
    const statesCut = t - r.statesDays * DAY_MS;
    const jobs = yield* this.pruneBatched(
      'DELETE FROM jobs WHERE id IN (SELECT id FROM jobs WHERE ended_at IS NOT NULL AND ended_at < ? LIMIT ?)',
      jobsCut,
    );
    const states = yield* this.pruneBatched(
      'DELETE FROM states WHERE id IN (SELECT id FROM states WHERE ended_at IS NOT NULL AND ended_at < ? LIMIT ?)',
      statesCut,
    );
    if (this.closed) return { jobs, states, touchcutDays: 0 };
    const touchcutDays = this.db
      .prepare('DELETE FROM touchcut_days WHERE day < ?')
      .run(localDay(jobsCut)).changes;
    // A machine with no record left is forgotten (the machine lists of the API).
    this.db.exec(`DELETE FROM last_seen WHERE
      NOT EXISTS (SELECT 1 FROM states s WHERE s.machine = last_seen.machine) AND
      NOT EXISTS (SELECT 1 FROM jobs j WHERE j.machine = last_seen.machine)`);
    if (jobs || states || touchcutDays)
      this.opts.log.info('history pruned', { jobs, states, touchcutDays, retention: r });
    return { jobs, states, touchcutDays };
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
    const l = this.live.get(machine);
    if (!l?.job) return undefined;
    const j = l.job;
    return {
      state: l.state,
      job: {
        id: j.id,
        name: j.name,
        countedTo: j.countedTo,
        runningMs: j.runningMs,
        pausedMs: j.pausedMs,
        progress: j.progress,
      },
    };
  }

  /** Every open job as counted in memory, by machine: what a read worker needs to count them. */
  liveJobs(): Record<string, LiveJobView> {
    const out: Record<string, LiveJobView> = {};
    for (const m of this.live.keys()) {
      const j = this.liveJob(m);
      if (j) out[m] = j;
    }
    return out;
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
