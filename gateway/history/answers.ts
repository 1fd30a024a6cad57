import type { StatsExport } from '../../src/fleet/server-part';
import type { CsvValue } from '../../src/ui/csv';
import type { Retention, Shift } from '../settings';
import type { HistoryReader } from './reader';
import { localDay, parseDate, shiftWindow } from './shifts';
import { OUTCOMES, STATES, type JobCounts, type JobRow, type Outcome, type StateSeconds } from './model';

/**
 * The answers of `GET /api/history/*` (documented in gateway/README.md), computed in a read worker
 * (read-worker.ts) from a reader on its own read-only connection: never on the gateway's thread.
 * Times are ms since the epoch (UTC) in JSON and ISO 8601 (UTC) in CSV; durations are seconds.
 * Each table has a `.csv` form (formula-safe, src/ui/csv.ts).
 */

const DAY_MS = 86_400_000;
/** The longest range one request may ask for. */
export const MAX_RANGE_DAYS = 400;
const CSV_MAX_JOBS = 10_000;

class BadRequest extends Error {}
class NotFound extends Error {}

function seconds(ms: number): number {
  return Math.round(ms) / 1000;
}

function secondsOf(s: StateSeconds): StateSeconds {
  const out = { ...s };
  for (const k of Object.keys(out) as Array<keyof StateSeconds>) out[k] = seconds(out[k]);
  return out;
}

function iso(t: number | null): string | null {
  return t === null ? null : new Date(t).toISOString();
}

/** `ms since the epoch` or an ISO 8601 date/time. */
function parseTime(v: string | null, name: string): number | undefined {
  if (v === null || v === '') return undefined;
  const t = /^\d{1,15}$/.test(v) ? Number(v) : Date.parse(v);
  if (!Number.isFinite(t)) throw new BadRequest(`${name}: a time as ms since the epoch or ISO 8601`);
  return t;
}

/** What a worker needs to answer, besides the question: sent with each one. */
export interface AnswerEnv {
  /** ms since the epoch: the gateway's clock when the question came. */
  now: number;
  /** The machines file's machines, in its order. */
  machines: Array<{ id: string; name: string; kind: string }>;
  /** The machines the asker may use (null: all). */
  allowed: string[] | null;
  settings: { shifts: Shift[]; retention: Retention };
}

export type HistoryAnswer =
  | { type: 'json'; status: number; body: unknown }
  | {
      type: 'csv';
      name: string;
      header: CsvValue[];
      rows: Iterable<readonly CsvValue[]>;
      /** More rows than the bound (states): said in a header. */
      truncated?: boolean;
    };

/**
 * Answers one `GET /api/history/<route>[.csv]` from `store` (a reader on its own connection, in a
 * read worker): JSON whole (bounded), CSV as rows to be written as they come.
 */
export function answerHistory(
  route: string,
  csv: boolean,
  p: URLSearchParams,
  env: AnswerEnv,
  store: HistoryReader,
  /** The families' exports of their stored days, by route (`history.statsExport`). */
  statsExports: ReadonlyMap<string, StatsExport> = new Map(),
): HistoryAnswer {
  try {
    return answer(route, csv, p, env, store, statsExports);
  } catch (e) {
    if (e instanceof BadRequest) return { type: 'json', status: 400, body: { error: e.message } };
    if (e instanceof NotFound) return { type: 'json', status: 404, body: { error: e.message } };
    throw e;
  }
}

function answer(
  route: string,
  csv: boolean,
  p: URLSearchParams,
  env: AnswerEnv,
  store: HistoryReader,
  statsExports: ReadonlyMap<string, StatsExport>,
): HistoryAnswer {
  const byId = new Map(env.machines.map((m) => [m.id, m]));
  const ctx = { now: () => env.now };
  const pr = { machines: env.allowed };
  const mayUseMachine = (x: { machines: string[] | null }, id: string): boolean =>
    x.machines === null || x.machines.includes(id);

  function range(p: URLSearchParams): { from: number; to: number } {
    const to = parseTime(p.get('to'), 'to') ?? ctx.now();
    const from = parseTime(p.get('from'), 'from') ?? to - DAY_MS;
    if (from >= to) throw new BadRequest('from must be before to');
    if (to - from > MAX_RANGE_DAYS * DAY_MS) throw new BadRequest(`at most ${MAX_RANGE_DAYS} days at once`);
    return { from, to };
  }

  /** `machine=` when the user may use it (404 otherwise, as for a machine that does not exist). */
  function machineParam(pr: { machines: string[] | null }, p: URLSearchParams): string | undefined {
    const m = p.get('machine');
    if (!m) return undefined;
    if (!mayUseMachine(pr, m)) throw new NotFound(`no machine "${m}" you may see`);
    return m;
  }

  /** The machines an answer lists: the machines file's the user may use, then others with records. */
  function machineList(
    pr: { machines: string[] | null },
    store: HistoryReader,
    only: string | undefined,
  ): string[] {
    if (only) return [only];
    const ids = env.machines.map((m) => m.id).filter((id) => mayUseMachine(pr, id));
    const known = new Set(ids);
    for (const id of store.machinesRecorded()) if (!known.has(id) && mayUseMachine(pr, id)) ids.push(id);
    return ids;
  }

  function machineInfo(id: string): { machine: string; machineName: string; family: string | null } {
    const m = byId.get(id);
    return { machine: id, machineName: m?.name ?? id, family: m?.kind ?? null };
  }

  function jobView(j: JobRow) {
    return {
      id: j.id,
      machine: j.machine,
      machineName: byId.get(j.machine)?.name ?? j.machine,
      family: j.family,
      name: j.name,
      startedAt: j.startedAt,
      endedAt: j.endedAt,
      outcome: j.outcome,
      runningS: seconds(j.runningMs),
      pausedS: seconds(j.pausedMs),
      progress: j.progress,
      startedBy: j.startedBy,
      pausedBy: j.pausedBy,
      resumedBy: j.resumedBy,
      stoppedBy: j.stoppedBy,
      endAlarm: j.endAlarm,
    };
  }

  const SECONDS_COLUMNS = [...STATES, 'unrecorded'] as const;

  const json = (body: unknown): HistoryAnswer => ({ type: 'json', status: 200, body });
  const csvOut = (
    name: string,
    header: CsvValue[],
    rows: Iterable<readonly CsvValue[]>,
    truncated?: boolean,
  ): HistoryAnswer => ({ type: 'csv', name, header, rows, ...(truncated ? { truncated } : {}) });

  const answerIt = (): HistoryAnswer => {
    const allowed = pr.machines;
    switch (route) {
      case 'jobs': {
        const outcomeParam = p.get('outcome');
        const outcome = [...OUTCOMES, 'open' as const].find((o) => o === outcomeParam);
        if (outcomeParam && !outcome)
          throw new BadRequest(`outcome: one of ${[...OUTCOMES, 'open'].join(', ')}`);
        const from = parseTime(p.get('from'), 'from');
        const to = parseTime(p.get('to'), 'to');
        const limitP = Number(p.get('limit') ?? (csv ? CSV_MAX_JOBS : 100));
        const offsetP = Number(p.get('offset') ?? 0);
        if (!Number.isInteger(limitP) || limitP < 1 || limitP > (csv ? CSV_MAX_JOBS : 1000))
          throw new BadRequest(`limit: 1 to ${csv ? CSV_MAX_JOBS : 1000}`);
        if (!Number.isInteger(offsetP) || offsetP < 0) throw new BadRequest('offset: 0 or more');
        const q = p.get('q')?.trim().slice(0, 200) || undefined;
        const jq = {
          machines: allowed,
          machine: machineParam(pr, p),
          family: p.get('family') || undefined,
          outcome: outcome as Outcome | 'open' | undefined,
          from,
          to,
          q,
          limit: limitP,
          offset: offsetP,
        };
        if (!csv) {
          const r = store.jobs(jq);
          const jobs = r.jobs.map(jobView);
          return json({ jobs, total: r.total, limit: limitP, offset: offsetP });
        }
        // The export: written as SQLite reads them (no total to count first).
        const jobs = mapped(store.jobRows(jq), jobView);
        return csvOut(
          'jobs',
          [
            'id',
            'machine',
            'machine_name',
            'family',
            'job',
            'started',
            'ended',
            'outcome',
            'running_s',
            'paused_s',
            'progress',
            'started_by',
            'paused_by',
            'resumed_by',
            'stopped_by',
            'end_alarm',
          ],
          mapped(jobs, (j) => [
            j.id,
            j.machine,
            j.machineName,
            j.family,
            j.name,
            iso(j.startedAt),
            iso(j.endedAt),
            j.outcome ?? 'open',
            j.runningS,
            j.pausedS,
            j.progress,
            j.startedBy,
            j.pausedBy,
            j.resumedBy,
            j.stoppedBy,
            j.endAlarm,
          ]),
        );
      }
      case 'states': {
        const { from, to } = range(p);
        const only = machineParam(pr, p);
        const q = { machines: allowed, machine: only, from, to };
        if (csv) {
          // The export: machine by machine as the rows come, the same rows as the JSON answer.
          const list = machineList(pr, store, only);
          const { intervals, truncated } = store.statesByMachine(q, list);
          return csvOut(
            'states',
            ['machine', 'machine_name', 'state', 'alarm', 'from', 'to', 'seconds', 'open'],
            mapped(intervals, (i) => {
              const m = machineInfo(i.machine);
              return [
                m.machine,
                m.machineName,
                i.state,
                i.alarm,
                iso(i.from),
                iso(i.to),
                seconds(i.to - i.from),
                i.open,
              ];
            }),
            truncated,
          );
        }
        const { intervals, truncated } = store.states(q);
        const per = new Map<string, typeof intervals>();
        for (const i of intervals) {
          const list = per.get(i.machine);
          if (list) list.push(i);
          else per.set(i.machine, [i]);
        }
        const machines = machineList(pr, store, only).map((id) => ({
          ...machineInfo(id),
          intervals: (per.get(id) ?? []).map((i) => ({
            state: i.state,
            alarm: i.alarm,
            from: i.from,
            to: i.to,
            open: i.open,
          })),
        }));
        return json({ from, to, truncated, machines });
      }
      case 'utilisation': {
        const { from, to } = range(p);
        const only = machineParam(pr, p);
        const until = Math.max(from, Math.min(to, ctx.now()));
        const u = store.utilisation({ machines: allowed, machine: only, from, to });
        const machines = machineList(pr, store, only).map((id) => {
          const s = u.get(id) ?? { ...emptyLike(), unrecorded: until - from };
          return { ...machineInfo(id), seconds: secondsOf(s) };
        });
        if (!csv) {
          return json({ from, to, spanS: seconds(until - from), machines });
        }
        return csvOut(
          'utilisation',
          ['machine', 'machine_name', 'from', 'to', ...SECONDS_COLUMNS.map((k) => `${k}_s`)],
          machines.map((m) => [
            m.machine,
            m.machineName,
            iso(from),
            iso(until),
            ...SECONDS_COLUMNS.map((k) => m.seconds[k]),
          ]),
        );
      }
      case 'stops': {
        const { from, to } = range(p);
        const stops = store
          .stops({ machines: allowed, machine: machineParam(pr, p), from, to })
          .map((s) => ({ alarm: s.alarm, count: s.count, seconds: seconds(s.ms), machines: s.machines }));
        if (!csv) {
          return json({ from, to, stops });
        }
        return csvOut(
          'stops',
          ['alarm', 'count', 'seconds', 'machines'],
          stops.map((s) => [s.alarm, s.count, s.seconds, s.machines.join(' ')]),
        );
      }
      case 'shift-report': {
        const date = p.get('date') || localDay(ctx.now());
        if (!parseDate(date)) throw new BadRequest('date: YYYY-MM-DD');
        const shifts = historySettings().shifts;
        const name = p.get('shift');
        const shift = shifts.find((s) => s.name === name);
        if (!shift)
          throw new NotFound(
            `shift: one of ${shifts.map((s) => JSON.stringify(s.name)).join(', ') || '(no shifts are set)'}`,
          );
        const w = shiftWindow(date, shift);
        if (!w) throw new BadRequest('date: YYYY-MM-DD');
        const only = machineParam(pr, p);
        const q = { machines: allowed, machine: only, from: w.from, to: w.to };
        const until = Math.max(w.from, Math.min(w.to, ctx.now()));
        const u = store.utilisation(q);
        const counts = store.jobCounts(q);
        const zeroJobs = (): JobCounts => ({
          finished: 0,
          cancelled: 0,
          failed: 0,
          unknown: 0,
          inProgress: 0,
        });
        const totals = { seconds: { ...emptyLike(), unrecorded: 0 }, jobs: zeroJobs() };
        const machines = machineList(pr, store, only).map((id) => {
          const s = u.get(id) ?? { ...emptyLike(), unrecorded: until - w.from };
          const j = counts.get(id) ?? zeroJobs();
          for (const k of SECONDS_COLUMNS) totals.seconds[k] += s[k];
          for (const k of Object.keys(j) as Array<keyof JobCounts>) totals.jobs[k] += j[k];
          return { ...machineInfo(id), seconds: secondsOf(s), jobs: j };
        });
        const body = {
          date,
          shift,
          from: w.from,
          to: w.to,
          spanS: seconds(until - w.from),
          machines,
          totals: { seconds: secondsOf(totals.seconds), jobs: totals.jobs },
        };
        if (!csv) {
          return json(body);
        }
        const jobKeys = ['finished', 'cancelled', 'failed', 'unknown', 'inProgress'] as const;
        return csvOut(
          `shift-${date}-${shift.name.replace(/[^A-Za-z0-9_-]/g, '_')}`,
          [
            'date',
            'shift',
            'machine',
            'machine_name',
            ...SECONDS_COLUMNS.map((k) => `${k}_s`),
            ...jobKeys.map((k) => (k === 'inProgress' ? 'jobs_in_progress' : `jobs_${k}`)),
          ],
          machines.map((m) => [
            date,
            shift.name,
            m.machine,
            m.machineName,
            ...SECONDS_COLUMNS.map((k) => m.seconds[k]),
            ...jobKeys.map((k) => m.jobs[k]),
          ]),
        );
      }
      case 'info': {
        if (csv) throw new NotFound('no CSV of the info');
        const i = store.info();
        return json({
          sizeBytes: i.sizeBytes,
          schemaVersion: i.schemaVersion,
          oldest: { jobAt: i.oldest.job, stateAt: i.oldest.state, touchcutDay: i.oldest.touchcutDay },
          counts: i.counts,
          ...historySettings(),
        });
      }
      default: {
        // A family's stored days of statistics (its server part's `history.statsExport`).
        const sx = statsExports.get(route);
        if (!sx) throw new NotFound(`no such endpoint: GET /api/history/${route}`);
        const from = p.get('from') || undefined;
        const to = p.get('to') || undefined;
        for (const [k, v] of [
          ['from', from],
          ['to', to],
        ] as const)
          if (v !== undefined && !parseDate(v)) throw new BadRequest(`${k}: YYYY-MM-DD`);
        const days = store
          .touchcutDays({ machines: allowed, machine: machineParam(pr, p), from, to })
          .map((d) => ({ ...d, machineName: byId.get(d.machine)?.name ?? d.machine }));
        if (!csv) {
          return json({ days });
        }
        return csvOut(
          route,
          ['machine', 'machine_name', 'day', ...sx.columns, 'pulled'],
          days.map((d) => [d.machine, d.machineName, d.day, ...sx.row(d.stats), iso(d.pulledAt)]),
        );
      }
    }
  };

  function historySettings(): { shifts: Shift[]; retention: Retention } {
    return env.settings;
  }

  return answerIt();
}

/** `f` over `rows` as they are read (an export never holds them all). */
function* mapped<T, U>(rows: Iterable<T>, f: (row: T) => U): Generator<U> {
  for (const r of rows) yield f(r);
}

function emptyLike(): Omit<StateSeconds, 'unrecorded'> {
  return { running: 0, paused: 0, idle: 0, alarm: 0, offline: 0, unknown: 0 };
}
