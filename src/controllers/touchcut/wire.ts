import { z } from 'zod/mini';
import { addIssue, preprocess } from '../../fleet/schema';

/**
 * Wire schemas of the Kinetic TouchCut REST API v1 (`/rest/v1/...`).
 *
 * SOURCE: the TouchCut manual's reference section only (../shared/protocols/touchcut-rest-api.txt).
 * No real capture exists publicly (see ../shared/fixtures/touchcut/SOURCES.md), so every schema
 * here is built from the manual's templates and examples and is deliberately tolerant:
 * - unknown keys pass through (`z.looseObject`),
 * - numbers and booleans may arrive as strings ("true", "1", "12.5"),
 * - enum-like strings (machineState, drossBinMode, …) stay open strings; the session maps known
 *   words and shows anything else as "unknown (raw …)",
 * - documented fields are optional: the `fields` parameter trims answers and the manual says the
 *   interface "is still subject to change".
 */

// ---------------------------------------------------------------------------------------------
// lenient scalars

function toNumber(v: unknown): unknown {
  if (typeof v === 'string' && v.trim() !== '' && Number.isFinite(Number(v))) return Number(v);
  return v;
}

function toBoolean(v: unknown): unknown {
  if (v === 'true' || v === 'TRUE' || v === 'True' || v === 1 || v === '1') return true;
  if (v === 'false' || v === 'FALSE' || v === 'False' || v === 0 || v === '0') return false;
  return v;
}

function toStringish(v: unknown): unknown {
  return typeof v === 'number' || typeof v === 'boolean' ? String(v) : v;
}

/** null counts as absent: a sloppy server may send `null` for "no value". */
const absent = (f: (v: unknown) => unknown) => (v: unknown) => (v === null ? undefined : f(v));

export const num = preprocess(toNumber, z.number());
export const optNum = preprocess(absent(toNumber), z.optional(z.number()));
export const bool = preprocess(toBoolean, z.boolean());
export const optBool = preprocess(absent(toBoolean), z.optional(z.boolean()));
export const str = preprocess(toStringish, z.string());
export const optStr = preprocess(absent(toStringish), z.optional(z.string()));

/** An array that may be missing or null (then empty). */
function list<T extends z.ZodMiniType>(item: T) {
  return preprocess((v) => (v === null || v === undefined ? [] : v), z.array(item));
}

// ---------------------------------------------------------------------------------------------
// errors — manual, "Failure Responses": `{ "code": "1003", "msg": "Required parameter missing: username" }`

export const errorBodySchema = z.looseObject({
  code: str,
  msg: optStr,
});
export type ErrorBody = z.output<typeof errorBodySchema>;

// ---------------------------------------------------------------------------------------------
// rest/v1/auth and rest/v1/auth/change-password — `{ "success": "true", "token": "<JWT>" }`
// (note: `success` is a *string* in the manual; accept a boolean too)

export const authResponseSchema = z.looseObject({
  success: optBool,
  token: z.string().check(z.minLength(1)),
});
export type AuthResponse = z.output<typeof authResponseSchema>;

// ---------------------------------------------------------------------------------------------
// The gateway's answer about the TouchCut login it holds (`GET`/`POST rest/v1/auth`, the password
// change): TouchCut's fields without the token, plus who is logged in and until when
// (gateway.ts `HeldLogin`). The JWT itself never reaches the browser.

export const heldLoginSchema = z.looseObject({
  success: optBool,
  loggedIn: bool,
  user: optStr,
  /** ms since epoch, from the JWT's `exp` (display only). */
  expiresAt: optNum,
});
export type HeldLoginWire = z.output<typeof heldLoginSchema>;

// ---------------------------------------------------------------------------------------------
// rest/v1/machine-info (no login)

export const machineInfoSchema = z.looseObject({
  programName: optStr,
  exePath: optStr,
  exeName: optStr,
  exeVersion: optStr,
  licensedTo: optStr,
  primeCutInfo: optStr,
  registrationInfo: optStr,
  contactInfo: z.nullish(
    z.looseObject({
      companyName: optStr,
      postalAddr: optStr,
      streetAddr: optStr,
      countryName: optStr,
      phone: optStr,
      fax: optStr,
      email: optStr,
      webSite: optStr,
    }),
  ),
  tools: list(
    z.looseObject({
      toolType: optStr,
      toolName: optStr,
      position: optNum,
    }),
  ),
});
export type MachineInfoWire = z.output<typeof machineInfoSchema>;

// ---------------------------------------------------------------------------------------------
// rest/v1/status

/** `{ "vec": [x, y, z], "rot": [a, b, c] }` */
export const poseSchema = z.looseObject({
  vec: list(num),
  rot: list(num),
});
export type Pose = z.output<typeof poseSchema>;

/**
 * `msgStatus: [{ "key": "<string>", "msg": "<string>" }]`. A bare string is accepted too (then it
 * is both key and message).
 */
export const msgStatusSchema = preprocess(
  (v) => (typeof v === 'string' ? { key: v, msg: v } : v),
  z.looseObject({ key: optStr, msg: optStr }),
);
export type MsgStatus = z.output<typeof msgStatusSchema>;

export const statusSchema = z.looseObject({
  currentUser: optStr,
  isHomed: optBool,
  machineState: optStr,
  programState: optStr,
  programOverride: optStr,
  stateName: optStr,
  toolIndex: optNum,
  toolName: optStr,
  toolOn: optBool,
  spacedCarriages: list(num),
  activeCarriages: list(num),
  heightControlAuto: optBool,
  drossBinMode: optStr,
  programName: optStr,
  /** `<double>`: the manual does not say 0..1 or 0..100; see `progressFraction`. */
  programProgress: optNum,
  plateOrigin: z.nullish(poseSchema),
  plateRotation: optNum,
  /** "MS-10.00 mm (0.394\")" */
  material: optStr,
  materialName: optStr,
  materialThickness: optNum,
  commandedPos: z.nullish(poseSchema),
  actualPos: z.nullish(poseSchema),
  feedrate: optNum,
  feedOverride: optNum,
  msgStatus: list(msgStatusSchema),
  units: optStr,
});
export type Status = z.output<typeof statusSchema>;

/**
 * `programProgress` is a `<double>` without a range in the manual. Decision: TouchCut shows program
 * progress as a percentage, so values are read as 0..100 and clamped; a value of exactly 1 is read
 * as 1 %, not 100 %.
 */
export function progressFraction(p: number | undefined): number | null {
  if (p === undefined || !Number.isFinite(p)) return null;
  return Math.min(1, Math.max(0, p / 100));
}

// ---------------------------------------------------------------------------------------------
// rest/v1/monitor

/** One I/O point: digital (`value: <boolean>`) or analogue (`scale`, `value: <double>`, `unitType`). */
export const ioPointSchema = z.looseObject({
  name: optStr,
  address: optStr,
  scale: optNum,
  value: preprocess(
    absent((v) => {
      const b = toBoolean(v);
      return typeof b === 'boolean' && typeof v !== 'number' ? b : toNumber(v);
    }),
    z.optional(z.union([z.boolean(), z.number()])),
  ),
  unitType: optStr,
});
export type IoPoint = z.output<typeof ioPointSchema>;

const ioGroupsObject = z.looseObject({
  din: list(ioPointSchema),
  dout: list(ioPointSchema),
  ain: list(ioPointSchema),
  aout: list(ioPointSchema),
});

export interface IoGroups {
  din: IoPoint[];
  dout: IoPoint[];
  ain: IoPoint[];
  aout: IoPoint[];
}

/**
 * The manual's template writes `"io": [ "din": [...], "dout": [...] ]`, which is not valid JSON,
 * and its real example answers `"io": []` when no I/O was asked for. Accept:
 * - an object of groups `{ "din": [...], "dout": [...], "ain": [...], "aout": [...] }`,
 * - an array of group objects `[{ "din": [...] }, { "dout": [...] }]` (merged in order),
 * - an empty array / null / missing (no I/O).
 */
export const ioSchema = preprocess((v) => {
  if (v === null || v === undefined) return {};
  if (Array.isArray(v)) {
    // Own keys only, kept as data: a group named `__proto__`, `constructor` or `toString` is just
    // an unknown group (never a prototype, never an inherited function to spread).
    const merged: Record<string, unknown[]> = {};
    for (const part of v) {
      if (part && typeof part === 'object' && !Array.isArray(part)) {
        for (const [k, items] of Object.entries(part as Record<string, unknown>)) {
          const group = Object.hasOwn(merged, k) ? merged[k] : undefined;
          const more: unknown[] = Array.isArray(items) ? items : [items];
          if (group) for (const item of more) group.push(item);
          else
            Object.defineProperty(merged, k, {
              value: [...more],
              enumerable: true,
              writable: true,
              configurable: true,
            });
        }
      }
    }
    return merged;
  }
  return v;
}, ioGroupsObject);

/** errorCode is a `<uint64>`: may not fit a double, so it is kept as text. */
const errorCode = preprocess(absent(toStringish), z.optional(z.string()));

export const axisSchema = z.looseObject({
  name: optStr,
  address: optStr,
  /** `<TAxis>`: an enum the manual prints as an integer (1 = axisLong, 10 = axisShort in its example). */
  index: preprocess(absent(toStringish), z.optional(z.string())),
  unitType: optStr,
  speedUnitType: optStr,
  scale: optNum,
  errorCode,
  commandedPos: optNum,
  actualPos: optNum,
  posError: optNum,
  errorLimit: optNum,
  actualVel: optNum,
  torque: optNum,
  torqueLimit: optNum,
  isEnabled: optBool,
  isMoving: optBool,
  isPosErrorInputOn: optBool,
  isHomeInputOn: optBool,
  isRevLimInputOn: optBool,
  isFwdLimInputOn: optBool,
  isRevSoftLimOn: optBool,
  isFwdSoftLimOn: optBool,
  canMoveFwd: optBool,
  canMoveRev: optBool,
  io: ioSchema,
});
export type Axis = z.output<typeof axisSchema>;

export const monitorSchema = z.looseObject({
  io: ioSchema,
  axes: list(axisSchema),
  units: optStr,
});
export type Monitor = z.output<typeof monitorSchema>;

// ---------------------------------------------------------------------------------------------
// rest/v1/stats
//
// The manual's template is split by a page break: the part that holds the sessions, the programs
// run ("{ startTime, name: programName }") and the errors sits in an unnamed wrapper object
// (`… ] }, "consumables": [ …`). Stats come "for a selected date range from the daily stats
// %d.ini files", so the wrapper is most likely per day. The schema therefore accepts those lists
// at the top level AND inside any other top-level object / array of objects (whatever its name),
// and the normalized result concatenates them.

export const carriageTotalsSchema = z.looseObject({
  carriage: optNum,
  time: optNum,
  distance: optNum,
  starts: optNum,
  errors: optNum,
  lastReset: optStr,
});
export type CarriageTotals = z.output<typeof carriageTotalsSchema>;

export const toolTotalsSchema = z.looseObject({
  tool: optNum,
  name: optStr,
  time: optNum,
  distance: optNum,
  starts: optNum,
  errors: optNum,
  lastReset: optStr,
  carriages: list(carriageTotalsSchema),
});
export type ToolTotals = z.output<typeof toolTotalsSchema>;

export const sessionSchema = z.looseObject({
  user: optStr,
  startTime: optStr,
  finishTime: optStr,
  activeTime: optNum,
  errorTime: optNum,
  idleTime: optNum,
  xyMovingTime: optNum,
  productiveTime: optNum,
  unproductiveTime: optNum,
  toolOnTime: optNum,
  toolTotals: list(toolTotalsSchema),
});
export type StatsSession = z.output<typeof sessionSchema>;

export const programRunSchema = z.looseObject({ startTime: optStr, name: optStr });
export type ProgramRun = z.output<typeof programRunSchema>;

export const errorRecordSchema = z.looseObject({ errorTime: optStr, error: optStr });
export type ErrorRecord = z.output<typeof errorRecordSchema>;

export const consumableSchema = z.looseObject({
  date: optStr,
  toolName: optStr,
  material: optStr,
  thickness: optNum,
  process: optStr,
  consType: optStr,
  consID: optStr,
  pierces: optNum,
  distance: optNum,
  time: optNum,
});
export type Consumable = z.output<typeof consumableSchema>;

/** The unnamed per-period wrapper (see above). `date` is how our simulator names its day. */
export const statsPeriodSchema = z.looseObject({
  date: optStr,
  sessions: list(sessionSchema),
  programs: list(programRunSchema),
  errors: list(errorRecordSchema),
});
export type StatsPeriod = z.output<typeof statsPeriodSchema>;

const PERIOD_KEYS = ['sessions', 'programs', 'errors'] as const;
const KNOWN_STATS_KEYS = new Set(['machine', 'machineResettable', 'consumables', 'units', ...PERIOD_KEYS]);

function looksLikePeriod(v: unknown): boolean {
  return !!v && typeof v === 'object' && !Array.isArray(v) && PERIOD_KEYS.some((k) => k in (v as object));
}

export interface Stats {
  machine: ToolTotals[];
  machineResettable: ToolTotals[];
  sessions: StatsSession[];
  programs: ProgramRun[];
  errors: ErrorRecord[];
  consumables: Consumable[];
  units: string | undefined;
  /** Periods found (day wrappers), in answer order; the top level counts as one when it has lists. */
  periods: StatsPeriod[];
}

export const statsSchema = z.pipe(
  z.looseObject({
    machine: list(toolTotalsSchema),
    machineResettable: list(toolTotalsSchema),
    consumables: list(consumableSchema),
    units: optStr,
  }),
  z.transform((raw, ctx): Stats => {
    const periods: StatsPeriod[] = [];
    const take = (v: unknown, path: (string | number)[]) => {
      const r = statsPeriodSchema.safeParse(v);
      if (r.success) periods.push(r.data);
      else
        for (const issue of r.error.issues)
          addIssue(ctx, {
            code: 'custom',
            message: issue.message,
            path: [...path, ...issue.path.map((p) => p as string | number)],
          });
    };
    const rec = raw as Record<string, unknown>;
    if (looksLikePeriod(rec)) {
      const top: Record<string, unknown> = {};
      for (const k of PERIOD_KEYS) if (k in rec) top[k] = rec[k];
      take(top, []);
    }
    for (const [k, v] of Object.entries(rec)) {
      if (KNOWN_STATS_KEYS.has(k)) continue;
      if (looksLikePeriod(v)) take(v, [k]);
      else if (Array.isArray(v) && v.length > 0 && v.every(looksLikePeriod))
        v.forEach((p, i) => take(p, [k, i]));
    }
    return {
      machine: raw.machine,
      machineResettable: raw.machineResettable,
      consumables: raw.consumables,
      units: raw.units,
      periods,
      sessions: periods.flatMap((p) => p.sessions),
      programs: periods.flatMap((p) => p.programs),
      errors: periods.flatMap((p) => p.errors),
    };
  }),
);

// ---------------------------------------------------------------------------------------------
// rest/v1/programs and rest/v1/unloader — "Interface subject to change": any JSON object or array
// is accepted and rendered generically; only `units` is read.

export const openDataSchema = z.union([z.looseObject({ units: optStr }), z.array(z.unknown())]);
export type OpenData = z.output<typeof openDataSchema>;

// ---------------------------------------------------------------------------------------------
// units

export type UnitsChoice = 'default' | 'metric' | 'imperial';
export const UNITS_CHOICES: readonly UnitsChoice[] = ['default', 'metric', 'imperial'];

/** Label for a TouchCut unit type (`utLength`, `utFeed`, …) in the units the answer says it used. */
export function unitLabel(unitType: string | undefined, units: string | undefined): string {
  const imperial = (units ?? '').toLowerCase().startsWith('imp');
  const metric = (units ?? '').toLowerCase().startsWith('met');
  const t = (unitType ?? '').replace(/^ut/, '').toLowerCase();
  switch (t) {
    case 'length':
    case 'thickness':
    case 'distance':
      return imperial ? 'in' : metric ? 'mm' : '(length)';
    case 'feed':
    case 'speed':
      return imperial ? 'in/min' : metric ? 'mm/min' : '(feed)';
    case 'angle':
      return '°';
    case 'time':
      return 's';
    case '':
      return '';
    default:
      // Unknown unit types stay visible as sent.
      return unitType ?? '';
  }
}
