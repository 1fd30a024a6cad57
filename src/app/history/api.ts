import { z } from 'zod/mini';
import { CONSOLE_HEADERS } from '../../fleet/origin';

/**
 * The production history API (gateway/README.md, "Production history"): every answer checked
 * here; a malformed one is an error, never data. Times are ms since the epoch, durations seconds.
 */

export const STATES = ['running', 'paused', 'idle', 'alarm', 'offline', 'unknown'] as const;
export type HistoryState = (typeof STATES)[number];
export const OUTCOMES = ['finished', 'cancelled', 'failed', 'unknown'] as const;
export type Outcome = (typeof OUTCOMES)[number];

const time = z.number();
const secs = z.number().check(z.nonnegative());
const state = z.enum(STATES);
const outcome = z.enum(OUTCOMES);

export const jobSchema = z.object({
  id: z.number(),
  machine: z.string(),
  machineName: z.string(),
  family: z.nullable(z.string()),
  name: z.nullable(z.string()),
  startedAt: time,
  endedAt: z.nullable(time),
  outcome: z.nullable(outcome),
  runningS: secs,
  pausedS: secs,
  progress: z.nullable(z.number().check(z.gte(0), z.lte(1))),
  startedBy: z.nullable(z.string()),
  pausedBy: z.nullable(z.string()),
  resumedBy: z.nullable(z.string()),
  stoppedBy: z.nullable(z.string()),
  endAlarm: z.nullable(z.string()),
});
export type Job = z.infer<typeof jobSchema>;

export const jobsSchema = z.object({
  jobs: z.array(jobSchema),
  total: z.number().check(z.int(), z.nonnegative()),
  limit: z.number().check(z.int()),
  offset: z.number().check(z.int()),
});
export type JobsAnswer = z.infer<typeof jobsSchema>;

export const intervalSchema = z.object({
  state,
  alarm: z.nullable(z.string()),
  from: time,
  to: time,
  open: z.boolean(),
});
export type Interval = z.infer<typeof intervalSchema>;

const machineRef = {
  machine: z.string(),
  machineName: z.string(),
  family: z.nullable(z.string()),
};

export const statesSchema = z.object({
  from: time,
  to: time,
  truncated: z.boolean(),
  machines: z.array(z.object({ ...machineRef, intervals: z.array(intervalSchema) })),
});
export type StatesAnswer = z.infer<typeof statesSchema>;

export const secondsSchema = z.object({
  running: secs,
  paused: secs,
  idle: secs,
  alarm: secs,
  offline: secs,
  unknown: secs,
  unrecorded: secs,
});
export type StateSeconds = z.infer<typeof secondsSchema>;

export const utilisationSchema = z.object({
  from: time,
  to: time,
  spanS: secs,
  machines: z.array(z.object({ ...machineRef, seconds: secondsSchema })),
});
export type UtilisationAnswer = z.infer<typeof utilisationSchema>;

export const stopsSchema = z.object({
  from: time,
  to: time,
  stops: z.array(
    z.object({
      alarm: z.nullable(z.string()),
      count: z.number().check(z.int()),
      seconds: secs,
      machines: z.array(z.string()),
    }),
  ),
});
export type StopsAnswer = z.infer<typeof stopsSchema>;

const jobCountsSchema = z.object({
  finished: z.number().check(z.int()),
  cancelled: z.number().check(z.int()),
  failed: z.number().check(z.int()),
  unknown: z.number().check(z.int()),
  inProgress: z.number().check(z.int()),
});
export type JobCounts = z.infer<typeof jobCountsSchema>;

const HHMM = /^([01]\d|2[0-3]):[0-5]\d$/;
export const shiftSchema = z.object({
  name: z.string(),
  start: z.string().check(z.regex(HHMM)),
  end: z.string().check(z.regex(HHMM)),
});
export type Shift = z.infer<typeof shiftSchema>;

export const shiftReportSchema = z.object({
  date: z.string(),
  shift: shiftSchema,
  from: time,
  to: time,
  spanS: secs,
  machines: z.array(z.object({ ...machineRef, seconds: secondsSchema, jobs: jobCountsSchema })),
  totals: z.object({ seconds: secondsSchema, jobs: jobCountsSchema }),
});
export type ShiftReport = z.infer<typeof shiftReportSchema>;

export const retentionSchema = z.object({
  jobsDays: z.number().check(z.int()),
  statesDays: z.number().check(z.int()),
});
export type Retention = z.infer<typeof retentionSchema>;

export const infoSchema = z.object({
  sizeBytes: z.number().check(z.nonnegative()),
  schemaVersion: z.number().check(z.int()),
  oldest: z.object({
    jobAt: z.nullable(time),
    stateAt: z.nullable(time),
    touchcutDay: z.nullable(z.string()),
  }),
  counts: z.object({
    jobs: z.number().check(z.int()),
    states: z.number().check(z.int()),
    touchcutDays: z.number().check(z.int()),
  }),
  shifts: z.array(shiftSchema),
  retention: retentionSchema,
});
export type HistoryInfo = z.infer<typeof infoSchema>;

/** What `PUT /api/settings` answers (only the parts this page uses). */
export const settingsAnswerSchema = z.object({ shifts: z.array(shiftSchema), retention: retentionSchema });

export type Result<T> = { ok: true; data: T } | { ok: false; error: string; status: number };

function errorWords(json: unknown): string | null {
  const e = z.object({ error: z.string() }).safeParse(json);
  return e.success ? e.data.error : null;
}

/** Checks an answer already read: the data, or an error in words. */
export function parseAnswer<T>(
  schema: z.ZodMiniType<T>,
  status: number,
  json: unknown,
  what: string,
): Result<T> {
  if (status < 200 || status > 299)
    return { ok: false, status, error: errorWords(json) ?? `The console answered HTTP ${status}.` };
  const r = schema.safeParse(json);
  if (!r.success) return { ok: false, status, error: `The ${what} answer is malformed.` };
  return { ok: true, data: r.data };
}

/** A request to the console's own API, its answer checked against `schema`. */
export async function request<T>(
  schema: z.ZodMiniType<T>,
  path: string,
  what: string,
  init: { method?: 'GET' | 'PUT'; body?: unknown; signal?: AbortSignal } = {},
): Promise<Result<T>> {
  let r: Response;
  try {
    r = await fetch(path, {
      method: init.method ?? 'GET',
      credentials: 'same-origin',
      headers: {
        ...CONSOLE_HEADERS,
        ...(init.body === undefined ? {} : { 'Content-Type': 'application/json' }),
      },
      ...(init.body === undefined ? {} : { body: JSON.stringify(init.body) }),
      ...(init.signal ? { signal: init.signal } : {}),
    });
  } catch (e) {
    if (init.signal?.aborted) throw e;
    return { ok: false, status: 0, error: 'The console cannot be reached.' };
  }
  let json: unknown = null;
  try {
    json = await r.json();
  } catch {
    json = null;
  }
  return parseAnswer(schema, r.status, json, what);
}

/** `?a=1&b=2` from the values that are set (empty: ""). */
export function query(params: Record<string, string | number | undefined | null>): string {
  const q = new URLSearchParams();
  for (const [k, v] of Object.entries(params))
    if (v !== undefined && v !== null && v !== '') q.set(k, String(v));
  const s = q.toString();
  return s ? `?${s}` : '';
}
