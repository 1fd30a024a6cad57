import { statSync } from 'node:fs';
import type { Retention } from '../settings';
import { schemaVersion, type Db } from './db';
import {
  STATES,
  type HistoryInfo,
  type HistoryState,
  type Interval,
  type JobCounts,
  type JobQuery,
  type JobRow,
  type Outcome,
  type RangeQuery,
  type StateSeconds,
  type StopReason,
  type TouchcutDay,
} from './model';

/**
 * The history's queries (what `/api/history/*` answers), apart from the recording: the store
 * (store.ts) runs them on its own connection, and the read workers (read-worker.ts) on read-only
 * connections of their own, off the gateway's thread (WAL: readers never block the recorder).
 * An open job's counted time comes from the recorder's memory: `live`.
 */

/** What the recorder holds in memory of a machine's open job (an open job counts up to now). */
export interface LiveJob {
  state: HistoryState;
  job: {
    id: number;
    name: string | null;
    countedTo: number;
    runningMs: number;
    pausedMs: number;
    progress: number | null;
  };
}

export interface HistoryReaderOptions {
  db: Db;
  file: string;
  now: () => number;
  retention: () => Retention;
  live: (machine: string) => LiveJob | undefined;
}

function emptySeconds(): StateSeconds {
  return { running: 0, paused: 0, idle: 0, alarm: 0, offline: 0, unknown: 0, unrecorded: 0 };
}

/** `(machine IN allowed)` for a nullable list, as SQL and parameters. */
function machineFilter(
  col: string,
  machines: readonly string[] | null,
  machine?: string,
): [string, unknown[]] {
  const parts: string[] = [];
  const params: unknown[] = [];
  if (machines) {
    parts.push(`${col} IN (SELECT value FROM json_each(?))`);
    params.push(JSON.stringify(machines));
  }
  if (machine) {
    parts.push(`${col} = ?`);
    params.push(machine);
  }
  return [parts.length ? parts.join(' AND ') : '1', params];
}

interface JobDbRow {
  id: number;
  machine: string;
  family: string;
  name: string | null;
  started_at: number;
  ended_at: number | null;
  outcome: Outcome | null;
  running_ms: number;
  paused_ms: number;
  progress: number | null;
  started_by: string | null;
  paused_by: string | null;
  resumed_by: string | null;
  stopped_by: string | null;
  end_alarm: string | null;
}

interface StateDbRow {
  machine: string;
  state: HistoryState;
  alarm: string | null;
  started_at: number;
  ended_at: number | null;
}

/** An interval clipped to [from, to); an open one ends at `now`. */
function clipped(r: StateDbRow, from: number, to: number, now: number): Interval {
  return {
    machine: r.machine,
    state: r.state,
    alarm: r.alarm,
    from: Math.max(r.started_at, from),
    to: Math.min(r.ended_at ?? now, to),
    open: r.ended_at === null,
  };
}

export class HistoryReader {
  readonly db: Db;
  readonly file: string;
  private readonly now: () => number;
  private readonly retention: () => Retention;
  private readonly live: (machine: string) => LiveJob | undefined;

  constructor(o: HistoryReaderOptions) {
    this.db = o.db;
    this.file = o.file;
    this.now = o.now;
    this.retention = o.retention;
    this.live = o.live;
  }

  touchcutDays(q: {
    machines: readonly string[] | null;
    machine?: string;
    from?: string;
    to?: string;
  }): TouchcutDay[] {
    const [where, params] = machineFilter('machine', q.machines, q.machine);
    const rows = this.db
      .prepare(
        `SELECT machine, day, pulled_at, stats FROM touchcut_days
         WHERE ${where} AND day >= ? AND day < ? ORDER BY day DESC, machine LIMIT 5000`,
      )
      .all(...params, q.from ?? '0000-00-00', q.to ?? '9999-99-99') as Array<{
      machine: string;
      day: string;
      pulled_at: number;
      stats: string;
    }>;
    return rows.map((r) => ({
      machine: r.machine,
      day: r.day,
      pulledAt: r.pulled_at,
      stats: JSON.parse(r.stats) as unknown,
    }));
  }

  // ------------------------------------------------------------------------------ queries

  private jobRow(r: JobDbRow, t: number): JobRow {
    let runningMs = r.running_ms;
    let pausedMs = r.paused_ms;
    let progress = r.progress;
    let name = r.name;
    // An open job: counted up to now from what is in memory.
    const live = r.ended_at === null ? this.live(r.machine) : undefined;
    if (live?.job.id === r.id) {
      const d = Math.max(0, t - live.job.countedTo);
      runningMs = live.job.runningMs + (live.state === 'running' ? d : 0);
      pausedMs = live.job.pausedMs + (live.state === 'paused' ? d : 0);
      progress = live.job.progress;
      name = live.job.name;
    }
    return {
      id: r.id,
      machine: r.machine,
      family: r.family,
      name,
      startedAt: r.started_at,
      endedAt: r.ended_at,
      outcome: r.outcome,
      runningMs,
      pausedMs,
      progress,
      startedBy: r.started_by,
      pausedBy: r.paused_by,
      resumedBy: r.resumed_by,
      stoppedBy: r.stopped_by,
      endAlarm: r.end_alarm,
    };
  }

  /** The jobs `q` asks for: a source (table or subquery), a condition and its parameters. */
  private jobsWhere(q: JobQuery): { source: string; w: string; params: unknown[] } {
    let source = 'jobs';
    let params: unknown[] = [];
    const parts: string[] = [];
    if (q.from !== undefined) {
      [source, params] = this.overlapping('jobs', q, q.from, q.to ?? Number.MAX_SAFE_INTEGER, '>=');
      source = `(${source})`;
    } else {
      const [where, p] = machineFilter('machine', q.machines, q.machine);
      parts.push(where);
      params.push(...p);
      if (q.to !== undefined) {
        parts.push('started_at < ?');
        params.push(q.to);
      }
    }
    if (q.family) {
      parts.push('family = ?');
      params.push(q.family);
    }
    if (q.outcome === 'open') parts.push('ended_at IS NULL');
    else if (q.outcome) {
      parts.push('outcome = ?');
      params.push(q.outcome);
    }
    if (q.q) {
      const like = `%${q.q.replace(/[\\%_]/g, (c) => `\\${c}`)}%`;
      parts.push(
        `(${['name', 'started_by', 'paused_by', 'resumed_by', 'stopped_by', 'end_alarm']
          .map((c) => `${c} LIKE ? ESCAPE '\\'`)
          .join(' OR ')})`,
      );
      for (let i = 0; i < 6; i++) params.push(like);
    }
    return { source, w: parts.length ? parts.join(' AND ') : '1', params };
  }

  jobs(q: JobQuery): { jobs: JobRow[]; total: number } {
    const { source, w, params } = this.jobsWhere(q);
    const total = Number(
      this.db
        .prepare(`SELECT COUNT(*) FROM ${source} WHERE ${w}`)
        .pluck()
        .get(...params),
    );
    const rows = this.db
      .prepare(`SELECT * FROM ${source} WHERE ${w} ORDER BY started_at DESC, id DESC LIMIT ? OFFSET ?`)
      .all(...params, q.limit ?? 100, q.offset ?? 0) as JobDbRow[];
    const t = this.now();
    return { jobs: rows.map((r) => this.jobRow(r, t)), total };
  }

  /** The jobs `jobs(q)` lists, read one at a time as SQLite gives them (an export: no total). */
  *jobRows(q: JobQuery): Generator<JobRow> {
    const { source, w, params } = this.jobsWhere(q);
    const stmt = this.db.prepare(
      `SELECT * FROM ${source} WHERE ${w} ORDER BY started_at DESC, id DESC LIMIT ? OFFSET ?`,
    );
    const t = this.now();
    for (const r of stmt.iterate(...params, q.limit ?? 100, q.offset ?? 0) as IterableIterator<JobDbRow>)
      yield this.jobRow(r, t);
  }

  /**
   * The rows of `table` (states or jobs) overlapping [from, to) of the machines asked for, as a
   * subquery with its parameters: those that start in the range (an index range), and each
   * machine's last one before it if it reaches into the range (one index lookup per machine: a
   * machine's intervals, and its jobs, never overlap). Not a scan of everything before `to`.
   * `reaches`: `>` for intervals (one ending at `from` is not in it), `>=` for jobs.
   */
  private overlapping(
    table: 'states' | 'jobs',
    q: { machines: readonly string[] | null; machine?: string },
    from: number,
    to: number,
    reaches: '>' | '>=',
  ): [string, unknown[]] {
    const [inRange, p1] = machineFilter('machine', q.machines, q.machine);
    const [perMachine, p2] = machineFilter('l.machine', q.machines, q.machine);
    const sql = `SELECT * FROM ${table} WHERE started_at >= ? AND started_at < ? AND ${inRange}
      UNION ALL
      SELECT * FROM ${table} WHERE id IN (
        SELECT (SELECT x.id FROM ${table} x WHERE x.machine = l.machine AND x.started_at < ?
                ORDER BY x.started_at DESC, x.id DESC LIMIT 1)
        FROM last_seen l WHERE ${perMachine})
      AND (ended_at ${reaches} ? OR ended_at IS NULL)`;
    return [sql, [from, to, ...p1, from, ...p2, from]];
  }

  /** The end of a range as far as it has happened. */
  private until(to: number): number {
    return Math.min(to, this.now());
  }

  /** The state intervals overlapping [from, to), clipped; open ones end now. At most `max`. */
  states(q: RangeQuery, max = 50_000): { intervals: Interval[]; truncated: boolean } {
    const t = this.now();
    const to = this.until(q.to);
    if (to <= q.from) return { intervals: [], truncated: false };
    const [sub, params] = this.overlapping('states', q, q.from, to, '>');
    const rows = this.db
      .prepare(
        `SELECT machine, state, alarm, started_at, ended_at FROM (${sub})
         ORDER BY machine, started_at, id LIMIT ?`,
      )
      .all(...params, max + 1) as StateDbRow[];
    const truncated = rows.length > max;
    return {
      truncated,
      intervals: rows.slice(0, max).map((r) => clipped(r, q.from, to, t)),
    };
  }

  /**
   * The intervals `states(q, max)` answers, machine by machine in `order` (each in time order, as
   * the states answer lists them), read as they come rather than held: the bound is the same (the
   * first `max` by machine id, then time: each machine's share is counted first). One read
   * transaction: every row is of the same moment. Run `intervals` to its end, or `return()` it.
   */
  statesByMachine(
    q: RangeQuery,
    order: readonly string[],
    max = 50_000,
  ): { truncated: boolean; intervals: Generator<Interval> } {
    const t = this.now();
    const to = this.until(q.to);
    if (to <= q.from) return { truncated: false, intervals: (function* () {})() };
    const db = this.db;
    db.exec('BEGIN');
    let open = true;
    const end = (): void => {
      if (open && db.inTransaction) db.exec('COMMIT');
      open = false;
    };
    const share = new Map<string, number>();
    let truncated = false;
    try {
      const [sub, params] = this.overlapping('states', q, q.from, to, '>');
      const counts = db
        .prepare(`SELECT machine, COUNT(*) AS n FROM (${sub}) GROUP BY machine ORDER BY machine`)
        .all(...params) as Array<{ machine: string; n: number }>;
      let left = max;
      for (const c of counts) {
        const n = Math.min(left, c.n);
        if (c.n > n) truncated = true;
        if (n > 0) share.set(c.machine, n);
        left -= n;
      }
    } catch (e) {
      end();
      throw e;
    }
    const overlapping = (machine: string) => this.overlapping('states', { ...q, machine }, q.from, to, '>');
    function* intervals(): Generator<Interval> {
      try {
        for (const machine of order) {
          const n = share.get(machine);
          if (!n) continue;
          const [sub, params] = overlapping(machine);
          const rows = db
            .prepare(
              `SELECT machine, state, alarm, started_at, ended_at FROM (${sub})
               ORDER BY started_at, id LIMIT ?`,
            )
            .iterate(...params, n) as IterableIterator<StateDbRow>;
          for (const r of rows) yield clipped(r, q.from, to, t);
        }
      } finally {
        end();
      }
    }
    return { truncated, intervals: intervals() };
  }

  /** Per machine: ms in each state within [from, to) (to clipped to now; open intervals count to now). */
  utilisation(q: RangeQuery): Map<string, StateSeconds> {
    const t = this.now();
    const to = this.until(q.to);
    const out = new Map<string, StateSeconds>();
    if (to <= q.from) return out;
    const [sub, params] = this.overlapping('states', q, q.from, to, '>');
    const rows = this.db
      .prepare(
        `SELECT machine, state, SUM(MIN(COALESCE(ended_at, ?), ?) - MAX(started_at, ?)) AS ms
         FROM (${sub}) GROUP BY machine, state`,
      )
      .all(t, to, q.from, ...params) as Array<{
      machine: string;
      state: HistoryState;
      ms: number;
    }>;
    for (const r of rows) {
      const s = out.get(r.machine) ?? emptySeconds();
      s[r.state] += r.ms;
      out.set(r.machine, s);
    }
    for (const s of out.values()) {
      const known = STATES.reduce((a, k) => a + s[k], 0);
      s.unrecorded = Math.max(0, to - q.from - known);
    }
    return out;
  }

  /** Alarm intervals overlapping the range, by alarm text: how many, how long (clipped), on which machines. */
  stops(q: RangeQuery, limit = 50): StopReason[] {
    const t = this.now();
    const to = this.until(q.to);
    if (to <= q.from) return [];
    const [sub, params] = this.overlapping('states', q, q.from, to, '>');
    const rows = this.db
      .prepare(
        `SELECT alarm, COUNT(*) AS count, SUM(MIN(COALESCE(ended_at, ?), ?) - MAX(started_at, ?)) AS ms,
                json_group_array(DISTINCT machine) AS machines
         FROM (${sub}) WHERE state = 'alarm'
         GROUP BY alarm ORDER BY ms DESC, count DESC LIMIT ?`,
      )
      .all(t, to, q.from, ...params, limit) as Array<{
      alarm: string | null;
      count: number;
      ms: number;
      machines: string;
    }>;
    return rows.map((r) => ({
      alarm: r.alarm,
      count: r.count,
      ms: r.ms,
      machines: (JSON.parse(r.machines) as string[]).sort(),
    }));
  }

  /** Per machine: jobs that ended in [from, to) by outcome, and those in progress at its end. */
  jobCounts(q: RangeQuery): Map<string, JobCounts> {
    const [where, params] = machineFilter('machine', q.machines, q.machine);
    const out = new Map<string, JobCounts>();
    const get = (m: string): JobCounts => {
      let c = out.get(m);
      if (!c) {
        c = { finished: 0, cancelled: 0, failed: 0, unknown: 0, inProgress: 0 };
        out.set(m, c);
      }
      return c;
    };
    const ended = this.db
      .prepare(
        `SELECT machine, outcome, COUNT(*) AS n FROM jobs
         WHERE ${where} AND ended_at >= ? AND ended_at < ? GROUP BY machine, outcome`,
      )
      .all(...params, q.from, q.to) as Array<{ machine: string; outcome: Outcome; n: number }>;
    for (const r of ended) get(r.machine)[r.outcome] += r.n;
    // Open at the window's end: each machine's last job started before it, if it had not ended.
    const [atEnd, endParams] = this.overlapping('jobs', q, q.to, q.to, '>=');
    const going = this.db
      .prepare(`SELECT machine, COUNT(*) AS n FROM (${atEnd}) GROUP BY machine`)
      .all(...endParams) as Array<{ machine: string; n: number }>;
    for (const r of going) get(r.machine).inProgress += r.n;
    return out;
  }

  /** The machines with any record (for a supervisor's list beyond the machines file). */
  machinesRecorded(): string[] {
    return this.db.prepare('SELECT machine FROM last_seen ORDER BY 1').pluck().all() as string[];
  }

  /** The database file and its write-ahead log, bytes. */
  sizeBytes(): number {
    let size = 0;
    for (const f of [this.file, `${this.file}-wal`]) {
      try {
        size += statSync(f).size;
      } catch {
        /* no WAL right now */
      }
    }
    return size;
  }

  info(): HistoryInfo {
    const size = this.sizeBytes();
    const one = (sql: string): unknown => this.db.prepare(sql).pluck().get();
    return {
      file: this.file,
      sizeBytes: size,
      schemaVersion: schemaVersion(this.db),
      oldest: {
        job: (one('SELECT MIN(started_at) FROM jobs') as number | null) ?? null,
        state: (one('SELECT MIN(started_at) FROM states') as number | null) ?? null,
        touchcutDay: (one('SELECT MIN(day) FROM touchcut_days') as string | null) ?? null,
      },
      counts: {
        jobs: Number(one('SELECT COUNT(*) FROM jobs')),
        states: Number(one('SELECT COUNT(*) FROM states')),
        touchcutDays: Number(one('SELECT COUNT(*) FROM touchcut_days')),
      },
      retention: this.retention(),
    };
  }
}
