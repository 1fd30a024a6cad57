import { z } from 'zod/mini';
import { preprocess } from '../../fleet/schema';

/**
 * zod schemas of every g2core REST payload (../shared/protocols/g2core-rest-design.txt, a
 * PRELIMINARY design: the console is its first consumer; the open points are settled in
 * client.ts and README.md). Lenient where the firmware and the design are sloppy:
 *  - numbers may come as strings ("hp":"ArduinoDue" vs "hp":3 between 101.03 and 100.26);
 *  - answers may be bare (design text: `{"posx":10,…}`) or wrapped (design examples:
 *    `{"value":{…},"code":0,"description":"OK"}`) — both are accepted;
 *  - unknown keys pass through; unknown enum values become an explicit "unknown".
 */

/** A number, or a string that is one ("12.5"). Anything else fails. */
export const lenientNumber = preprocess((v) => {
  if (typeof v === 'string' && v.trim() !== '' && Number.isFinite(Number(v))) return Number(v);
  return v;
}, z.number());

/** A scalar as g2core sends it: number, string, boolean or null (`{"jd":null}` in x-axis-group.json). */
export const scalar = z.union([z.number(), z.string(), z.boolean(), z.null()]);
export type Scalar = z.infer<typeof scalar>;

function isRecord(v: unknown): v is Record<string, unknown> {
  return typeof v === 'object' && v !== null && !Array.isArray(v);
}

/**
 * Unwraps the envelopes seen in the design and the fixtures: `{"value":X,"code":0,…}` (design
 * examples), `{"r":X,"f":[…]}` (serial replies, in case a server passes them through) and
 * `{"sr":X}` (status reports). Anything else is returned as it is.
 */
export function unwrapEnvelope(body: unknown, inner: 'value' | 'any' = 'any'): unknown {
  let b = body;
  if (isRecord(b) && 'value' in b && (inner === 'value' || isRecord(b.value) || Array.isArray(b.value))) {
    b = b.value;
  }
  if (inner === 'any' && isRecord(b) && isRecord(b.r) && 'f' in b) b = b.r;
  if (inner === 'any' && isRecord(b) && isRecord(b.sr) && Object.keys(b).length === 1) b = b.sr;
  return b;
}

// ---------------------------------------------------------------------------------------------
// Errors: {"status":{"code":100,"description":"…","additional_description":"…"}} (design,
// "Error Responses"). The firmware's serial companion `{"err":{"code":100,"msg":"…"}}`
// (error-unrecognized-name-101.03.jsonl) is accepted too.

export const statusObject = z.looseObject({
  code: lenientNumber,
  description: z.catch(z.optional(z.string()), undefined),
  additional_description: z.catch(z.nullish(z.string()), undefined),
});
export type StatusObject = z.infer<typeof statusObject>;

export const errorBody = z.union([
  z.looseObject({ status: statusObject }),
  z.pipe(
    z.looseObject({ err: z.looseObject({ code: lenientNumber, msg: z.optional(z.string()) }) }),
    z.transform((e) => ({
      status: { code: e.err.code, description: e.err.msg, additional_description: undefined },
    })),
  ),
]);

// ---------------------------------------------------------------------------------------------
// GET /version — {"fv":0.99,"fb":100.12,"fbs":"…","fbc":"…","hp":3,"hv":0,"id":"…","msg":"SYSTEM READY"}.
// hp/hv are numbers on 100.xx and strings ("ArduinoDue","na") on 101.03 (startup fixture).

export const versionInfo = z.looseObject({
  fv: z.catch(z.optional(lenientNumber), undefined),
  fb: z.catch(z.optional(lenientNumber), undefined),
  fbs: z.catch(z.optional(z.string()), undefined),
  fbc: z.catch(z.optional(z.string()), undefined),
  hp: z.catch(z.optional(z.union([z.number(), z.string()])), undefined),
  hv: z.catch(z.optional(z.union([z.number(), z.string()])), undefined),
  id: z.catch(z.optional(z.string()), undefined),
  msg: z.catch(z.optional(z.string()), undefined),
});
export type VersionInfo = z.infer<typeof versionInfo>;

export const versionResponse = preprocess((b) => unwrapEnvelope(b), versionInfo);

// ---------------------------------------------------------------------------------------------
// Status reports: GET /status_report[?filter=…] — a flat object of SR keys (posx, vel, stat …).

export type SrValues = Record<string, Scalar>;

const srRecord = z.pipe(
  z.record(z.string(), scalar),
  z.transform((r) => {
    const out: SrValues = {};
    for (const [k, v] of Object.entries(r)) {
      // Numbers sent as strings are coerced; other strings kept as they are.
      out[k] = typeof v === 'string' && v.trim() !== '' && Number.isFinite(Number(v)) ? Number(v) : v;
    }
    return out;
  }),
);

export const statusReportResponse = preprocess((b) => unwrapEnvelope(b), srRecord);

// ---------------------------------------------------------------------------------------------
// Machine resource: GET /machine, GET|PUT /machine/{key} — {"value": …}.

export const machineValueResponse = z.looseObject({
  value: z.unknown(),
  code: z.catch(z.optional(lenientNumber), undefined),
  description: z.catch(z.optional(z.string()), undefined),
});

/** A settings group: {"am":1,"vm":40000,…}. Values are scalars; nested objects are not expected. */
export const settingsGroup = z.record(z.string(), scalar);
export type SettingsGroup = z.infer<typeof settingsGroup>;

/** GET /machine → {"value":{"sys":{…},"x":{…},…}}. */
export const machineTreeResponse = z.looseObject({
  value: z.record(z.string(), z.union([settingsGroup, scalar])),
});

/** GET /machine?shallow=true → {"value":{"sys":true,…}} (true or, per the design's open question, null). */
export const shallowResponse = z.looseObject({
  value: z.record(z.string(), z.union([z.boolean(), z.null(), z.number()])),
});

/**
 * The value of one key, from an answer that may use the nested, flattened or dotted form:
 * {"value":40000}, {"value":{"x":{"vm":40000}}}, {"value":{"xvm":40000}}, {"value":{"x.vm":40000}}.
 * `group` is null for a freestanding key (`ct`, `stat`) or when the key is itself a group.
 */
export function valueForKey(value: unknown, group: string | null, key: string): unknown {
  if (!isRecord(value)) return value;
  if (group) {
    const g = value[group];
    if (isRecord(g) && key in g) return g[key];
    if (`${group}${key}` in value) return value[`${group}${key}`];
    if (`${group}.${key}` in value) return value[`${group}.${key}`];
    if (`${group}/${key}` in value) return value[`${group}/${key}`];
    return value;
  }
  // A group or a freestanding key echoed under its own name: {"value":{"g54":{…}}}.
  if (key in value && Object.keys(value).length === 1) return value[key];
  return value;
}

// ---------------------------------------------------------------------------------------------
// Operations. POST /operation → 201 with the id (the design shows a bare `42`). GET
// /operation/{id} → {"opstate":"pend|run|done|error","optype","value","line","error"?}.

export const createdId = z.pipe(
  z.union([
    z.number(),
    z.string().check(z.trim(), z.minLength(1)),
    z.pipe(
      z.looseObject({ id: z.union([z.number(), z.string().check(z.minLength(1))]) }),
      z.transform((o) => o.id),
    ),
    z.pipe(
      z.looseObject({ value: z.union([z.number(), z.string().check(z.minLength(1))]) }),
      z.transform((o) => o.value),
    ),
  ]),
  z.transform((id) => String(id)),
);

export const OPSTATES = ['pend', 'run', 'pause', 'done', 'error'] as const;
export type OpState = (typeof OPSTATES)[number] | 'unknown';

/** opstate: lower case in the design text, upper case in its example enums ("PEND"); both accepted. */
export const opState = z.pipe(
  z.string(),
  z.transform((s): { state: OpState; raw: string } => {
    const l = s.trim().toLowerCase();
    return { state: (OPSTATES as readonly string[]).includes(l) ? (l as OpState) : 'unknown', raw: s };
  }),
);

export const operation = z.looseObject({
  id: z.catch(z.optional(z.union([z.number(), z.string()])), undefined),
  opstate: opState,
  optype: z.catch(z.optional(z.string()), undefined),
  value: z.catch(z.optional(z.union([z.string(), z.array(z.string()), z.number()])), undefined),
  /** Lines of the operation finished so far. */
  line: z.catch(z.optional(lenientNumber), undefined),
  error: z.catch(z.nullish(statusObject), undefined),
  /**
   * Settled by the console: replies of the operation's JSON lines, in order, as the firmware's
   * `r` objects (`[{"xvm":40000}]`). G-code lines have no reply beyond the operation state.
   */
  r: z.catch(z.optional(z.array(z.record(z.string(), z.unknown()))), undefined),
});
export type Operation = z.infer<typeof operation>;

export const operationResponse = preprocess((b) => {
  // Tolerate an envelope around the operation, but an operation's own `value` holds its lines.
  if (isRecord(b) && !('opstate' in b) && isRecord(b.value) && 'opstate' in b.value) return b.value;
  return b;
}, operation);

/**
 * GET /operation (settled by the console, see client.ts): the operations the server knows,
 * unfinished first. Bare array or `{"value":[…]}`.
 */
export const operationListResponse = preprocess((b) => {
  if (isRecord(b) && Array.isArray(b.value)) return b.value;
  return b;
}, z.array(operation));

// ---------------------------------------------------------------------------------------------
// Jobs (settled by the console; see client.ts). GET /job/{id} →
// {"id","name","state","lines","done","started","finished","operation","position","error"?}.

export const JOB_STATES = ['queued', 'running', 'paused', 'done', 'killed', 'error'] as const;
export type JobState = (typeof JOB_STATES)[number] | 'unknown';

/** Times as epoch ms or ISO text. */
const timeMs = z.catch(
  z.pipe(
    z.nullish(z.union([z.number(), z.string()])),
    z.transform((v) => {
      if (v === null || v === undefined || v === '') return null;
      if (typeof v === 'number') return v;
      const n = Number(v);
      if (Number.isFinite(n)) return n;
      const t = Date.parse(v);
      return Number.isFinite(t) ? t : null;
    }),
  ),
  null,
);

export const job = z.looseObject({
  id: z.pipe(
    z.union([z.number(), z.string().check(z.minLength(1))]),
    z.transform((v) => String(v)),
  ),
  name: z.catch(z.nullish(z.string()), null),
  state: z.pipe(
    z.string(),
    z.transform((s): { state: JobState; raw: string } => {
      const l = s.trim().toLowerCase();
      return { state: (JOB_STATES as readonly string[]).includes(l) ? (l as JobState) : 'unknown', raw: s };
    }),
  ),
  lines: z.catch(z.nullish(lenientNumber), null),
  done: z.catch(z.nullish(lenientNumber), null),
  started: timeMs,
  finished: timeMs,
  operation: z.catch(
    z.pipe(
      z.nullish(z.union([z.number(), z.string()])),
      z.transform((v) => (v === null || v === undefined ? null : String(v))),
    ),
    null,
  ),
  position: z.catch(z.nullish(lenientNumber), null),
  error: z.catch(z.nullish(statusObject), null),
});
export type Job = z.infer<typeof job>;

export const jobResponse = preprocess((b) => {
  if (isRecord(b) && !('state' in b) && isRecord(b.value)) return b.value;
  return b;
}, job);

/** GET /job → [job…] (or {"value":[…]} / {"jobs":[…]}). */
export const jobListResponse = preprocess((b) => {
  if (isRecord(b) && Array.isArray(b.value)) return b.value;
  if (isRecord(b) && Array.isArray(b.jobs)) return b.jobs;
  return b;
}, z.array(job));

/**
 * Exception report of the serial protocol, `{"er":{"fb":101.03,"st":207,"msg":"…"}}`
 * (exception-report-kill-job-101.03.json). A REST server may pass it through as an operation's
 * error; the console reads `st` as the status code.
 */
export const exceptionReport = z.pipe(
  z.looseObject({
    er: z.looseObject({
      fb: z.catch(z.optional(lenientNumber), undefined),
      st: lenientNumber,
      msg: z.optional(z.string()),
    }),
  }),
  z.transform((e) => ({ code: e.er.st, description: e.er.msg, additional_description: undefined })),
);
