import statusTable from './data/status-codes.json' with { type: 'json' };
import enumTable from './data/state-enums.json' with { type: 'json' };

/**
 * g2core status codes and state enums, as data (copied verbatim from
 * ../shared/fixtures/g2core/status-codes.json and state-enums.json, which were extracted from
 * synthetos/g2 g2core/error.h and canonical_machine.h). Used by the client (error text, DRO
 * words) and the simulator (HTTP status of each code). Node-safe.
 */

export interface StatusCodeInfo {
  code: number;
  name: string;
  msg: string;
  range: string;
}

export const STATUS_CODES: ReadonlyMap<number, StatusCodeInfo> = new Map(
  statusTable.codes.map((c) => [c.code, { code: c.code, name: c.name, msg: c.msg, range: c.range }]),
);

/** The firmware text of a status code ("Parameter is read-only"), or a neutral fallback. */
export function statusText(code: number): string {
  const info = STATUS_CODES.get(code);
  if (!info) return `Status ${code}`;
  // Reserved codes whose text is just the number: say so rather than print a bare number.
  return info.msg === String(code) ? `Status ${code} (${info.name})` : info.msg;
}

/**
 * HTTP status for a g2core status code, per "Commonly Used HTTP Response Codes" of the REST
 * design. The design lists ranges; codes it does not list are settled here by the range the
 * firmware table puts them in (written down so a server author can match it):
 *  - 0 OK, 3 NOOP, 4 COMPLETE: 200 (not errors);
 *  - 1, 2 and the unused internal codes 37-87: 500 like the other internal errors;
 *  - unused input/JSON codes 117-129 and G-code codes 182-199: 400 (syntax / G-code errors);
 *  - runtime codes 210-219 (G29 not configured, reserved): 400 like 200-203 / 207-209;
 *  - reserved soft-limit codes 234-239: 405 like 220-233;
 *  - reserved homing 248-249 and probe 255: 400 like their neighbours.
 */
export function httpStatusFor(code: number): number {
  if (code === 0 || code === 3 || code === 4) return 200;
  if (code === 100 || code === 11) return 404;
  if (code === 104 || code === 105 || code === 106) return 405;
  if (code >= 220 && code <= 239) return 405;
  if (code === 5 || code === 6 || code === 18 || code === 204 || code === 205 || code === 206) return 410;
  if (code === 10 || code === 107) return 413;
  if (code >= 108 && code <= 110) return 416;
  if (code >= 101 && code <= 199) return 400;
  if (code >= 200 && code <= 219) return 400;
  if (code >= 240 && code <= 255) return 400;
  return 500;
}

/** Machine state (`stat`) — the only state a UI should rely on (state-enums.json). */
export interface StatInfo {
  value: number;
  name: string;
  label: string;
  wiki: string;
}

export const STAT: ReadonlyMap<number, StatInfo> = new Map(enumTable.stat.values.map((v) => [v.value, v]));

export const STAT_INITIALIZING = 0;
export const STAT_READY = 1;
export const STAT_ALARM = 2;
export const STAT_STOP = 3;
export const STAT_END = 4;
export const STAT_RUN = 5;
export const STAT_HOLD = 6;
export const STAT_PROBE = 7;
export const STAT_CYCLE = 8;
export const STAT_HOMING = 9;
export const STAT_JOG = 10;
export const STAT_INTERLOCK = 11;
export const STAT_SHUTDOWN = 12;
export const STAT_PANIC = 13;

/**
 * The words of the gateway's serial bridge (src/controllers/g2core/server/) for a board that went silent
 * while running (the firmware's known "stuck in run" state): the page offers a supervisor the
 * board's hard reset (`POST /board/reset`) while its status reads answer with them.
 */
export const STUCK_IN_RUN = 'stuck in run';

/** Words for a stat value; unknown values say so with the raw number. */
export function statLabel(stat: number | null | undefined): string {
  if (stat === null || stat === undefined) return 'Unknown';
  return STAT.get(stat)?.label ?? `Unknown (raw ${stat})`;
}

type EnumField = keyof typeof enumTable.enumerated_sr_fields;
export type DecodedField = Exclude<EnumField, '_source'>;

/** Decodes the modal-state fields of a status report (unit, coor, momo, plan, path, dist, admo, frmo). */
export function decodeEnum(field: DecodedField, value: number | null | undefined): string {
  if (value === null || value === undefined) return '—';
  const table = enumTable.enumerated_sr_fields[field] as Record<string, string>;
  return table[String(value)] ?? `unknown (raw ${value})`;
}

export const HOMED_LABELS: Record<number, string> = Object.fromEntries(
  enumTable.home.map((h) => [h.value, h.label]),
);
