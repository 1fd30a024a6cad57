import type Database from 'better-sqlite3';
import type { WatchSummary } from '../../src/fleet/contract';
import type { Logger } from '../log';
import type { Db } from './db';
import { STATES, type HistoryMachine, type HistoryState, type JobCommand, type Outcome } from './model';
import type { LiveJob as LiveJobView } from './reader';

/**
 * The history's recording: jobs and state intervals from the watch's summaries (`observe`), who
 * started, paused, resumed or stopped a job from the commands the gateway forwarded (`command`),
 * last-seen times (`heartbeat`); each change one transaction. A job opens on `running`/`paused`
 * and ends `cancelled`, `failed`, `finished` or `unknown` by the rules in gateway/README.md
 * ("How it is recorded"); `recover()` closes what a stop or crash left open at last-seen times.
 */

export const HEARTBEAT_MS = 5000;
/** A summary with no change refreshes the last-seen time at most this often. */
export const SEEN_EVERY_MS = 5000;
export const CHECKPOINT_EVERY_MS = 60_000;
/** A start command this long before a job opens (or after: the watch may see it first) started it. */
export const START_WINDOW_MS = 5 * 60_000;
/** A stop command this long after a job went idle made it `cancelled` (the watch may see the stop first). */
export const LATE_STOP_MS = 30_000;
const MAX_TEXT = 500;
const MAX_USER = 200;

export interface HistoryRecorderOptions {
  db: Db;
  log: Logger;
  now: () => number;
  /** The job commands by what they do (`jobCommandsOf(families)`). */
  jobCommands: Readonly<Record<string, JobCommand>>;
  /** The store was closed: nothing more is written. */
  isClosed: () => boolean;
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

export class HistoryRecorder {
  private readonly db: Db;
  private readonly now: () => number;
  private readonly live = new Map<string, Live>();
  private readonly pendingStarts = new Map<string, { user: string; at: number }>();
  private lastCheckpoint: number;
  private lastError = 0;
  /** What `recover()` closed when the store opened. */
  readonly recovered: { jobs: number; states: number };

  private readonly st: {
    openInterval: Database.Statement;
    closeInterval: Database.Statement;
    openJob: Database.Statement;
    countJob: Database.Statement;
    closeJob: Database.Statement;
    seen: Database.Statement;
  };

  constructor(private readonly opts: HistoryRecorderOptions) {
    const db = opts.db;
    this.db = db;
    this.now = opts.now;
    this.lastCheckpoint = this.now();
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

  private get closed(): boolean {
    return this.opts.isClosed();
  }

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
}
