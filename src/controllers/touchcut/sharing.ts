import {
  type SharingHints,
  type WatchDecl,
  type WatchSummary,
  watchAlarmsOf,
  watchStateOf,
} from '../../fleet/contract';
import { touchcutAccess, touchcutResource } from './access';
import { activityOf, alarmsOf, hasProgram } from './normalize';
import { errorBodySchema, progressFraction, statusSchema } from './wire';

/**
 * How the gateway shares one Kinetic TouchCut machine among every viewer (Node-safe, pure: the
 * gateway and the browser import it through `declaration.ts`). TouchCut has no socket: the reads
 * the console polls are answered once per period for everyone. Every viewer reads with the same
 * credentials (the machine's API key, or the TouchCut login the gateway holds for the machine:
 * gateway.ts drops whatever `Authorization` a browser sends), so no answer belongs to one user.
 */

/** `rest/v1/status` once a second (session.ts STATUS_INTERVAL_MS). */
export const STATUS_MS = 1000;
/** `rest/v1/monitor` twice a second while shown (feeds.ts MONITOR_INTERVAL_MS). */
export const MONITOR_MS = 500;
/**
 * `rest/v1/screenshot` at most once a second (feeds.ts SCREENSHOT_MIN_GAP_MS). The manual: "If a
 * second request is made within a second of the previous request, the previous screenshot will
 * be returned" — TouchCut shares it this way itself.
 */
export const SCREENSHOT_MS = 1000;
/** `rest/v1/programs` and `rest/v1/unloader` every 5 s while shown (queries.ts PROGRAMS_REFRESH_MS). */
export const OPEN_DATA_MS = 5000;
/** `rest/v1/machine-info` every 60 s until known (session.ts): the controller's fixed identity. */
export const MACHINE_INFO_MS = 60_000;
/** The watch's status poll (see `touchcutWatch`). */
export const WATCH_EVERY_MS = 5000;

/** Each polled resource: its window and the query parameters the console sends with it. */
const POLLED: Record<string, { ms: number; params: readonly string[] }> = {
  status: { ms: STATUS_MS, params: ['units'] },
  monitor: { ms: MONITOR_MS, params: ['fields', 'units'] },
  screenshot: { ms: SCREENSHOT_MS, params: [] },
  // `onlyChangedData` is left out on purpose (below).
  programs: { ms: OPEN_DATA_MS, params: ['offset', 'limit', 'fields', 'units'] },
  unloader: { ms: OPEN_DATA_MS, params: ['history', 'start-date', 'end-before-date', 'units'] },
  'machine-info': { ms: MACHINE_INFO_MS, params: [] },
};

/**
 * The reads the console polls, each with its own period, in the path form the access rule uses
 * (`touchcutResource`: any letter case, repeated and trailing slashes ignored), with only the
 * query parameters the console sends (the query is part of what makes two reads identical:
 * `units`, `fields`, the page). Not shared:
 * - `programs?onlyChangedData=…`: "only what changed" since what, the manual does not say (it may
 *   be since this client's last read); a refresh of the page the console just read asks for it;
 * - stats (read when a user picks a range, and read again on purpose when asked twice), `auth`
 *   (the gateway's own answer), and any undocumented path (supervisor-only, it may act).
 */
export function touchcutShareRead(path: string, query: URLSearchParams): number | null {
  const resource = touchcutResource(path);
  const polled = resource === null ? undefined : POLLED[resource];
  if (!polled) return null;
  for (const k of query.keys()) if (!polled.params.includes(k)) return null;
  const d = touchcutAccess({ method: 'GET', path, query });
  return d.command || d.role !== 'viewer' ? null : polled.ms;
}

// ---------------------------------------------------------------------------------- watch

/**
 * `GET rest/v1/status` → the summary, with the console's own reading of it (normalize.ts): the
 * state from `machineState` words, an alarm for every `msgStatus` (a critical one makes the state
 * `alarm`, as on the fleet tile), the job from `programName`, its progress from `programProgress`. A 401 (no accepted key, a login
 * that lapsed), any other failure, a `{code, msg}` body and a body the schema refuses are errors.
 */
export function readTouchcutStatus(status: number, body: string): WatchSummary | Error {
  let json: unknown;
  try {
    json = JSON.parse(body);
  } catch {
    return new Error(`rest/v1/status answered ${status}: not JSON (${body.trim().slice(0, 60)})`);
  }
  const keys =
    json && typeof json === 'object' && !Array.isArray(json) ? Object.keys(json).sort().join(',') : '';
  if (status < 200 || status > 299 || keys === 'code,msg') {
    const e = errorBodySchema.safeParse(json);
    const words = e.success ? ` (TouchCut code ${e.data.code.trim()}: ${e.data.msg ?? ''})` : '';
    return new Error(`rest/v1/status answered ${status}${words}`);
  }
  const p = statusSchema.safeParse(json);
  if (!p.success) {
    const i = p.error.issues[0];
    return new Error(`rest/v1/status: ${i ? `${i.path.join('.')}: ${i.message}` : 'invalid'}`);
  }
  const s = p.data;
  const { activity } = activityOf(s);
  const alarms = alarmsOf(s.msgStatus, [], 0);
  const critical = alarms.some((a) => a.severity === 'critical');
  const alarm = alarms.filter((a) => a.severity !== 'info');
  return {
    state: critical ? 'alarm' : watchStateOf(activity),
    alarm: alarm.length ? alarm.map((a) => a.message).join('; ') : null,
    job: hasProgram(s.programName) ? s.programName : null,
    alarms: watchAlarmsOf(alarms),
    progress: hasProgram(s.programName) ? progressFraction(s.programProgress) : null,
  };
}

/**
 * The watch: `GET rest/v1/status` every 5 s (the gateway adds the API key, or its held login).
 * TouchCut has no socket, so the poll is the only way to hear an alarm, and a plasma or oxy-fuel
 * table cuts with fire: a collision, a torch fault or a fire in the slag wants a record within
 * seconds. It is one small JSON answer, a fifth of what one open console page asks.
 */
export const touchcutWatch: WatchDecl = {
  everyMs: WATCH_EVERY_MS,
  poll: { path: '/rest/v1/status', read: readTouchcutStatus },
};

export const touchcutSharing: SharingHints = {
  shareRead: touchcutShareRead,
  /**
   * Reads ask to keep the connection (its pinned TLS one: no handshake per read, tls-pool.ts; at
   * most 2 idle, a Windows PC has sockets to spare). The manual's answers are HTTP/1.0: one that
   * does not say `Connection: keep-alive` is closed after it, a new connection per request.
   */
  keepAlive: true,
  /**
   * A Windows PC whose first job is the cutting: status, monitor and screenshot in flight at once
   * (the three live feeds), and no more.
   */
  maxConcurrentReads: 3,
  watch: touchcutWatch,
};
