import {
  type FanoutStreamDecl,
  type FrameClass,
  type SharingHints,
  type WatchDecl,
  type WatchSummary,
  watchAlarmsOf,
  watchStateOf,
} from '../../fleet/contract';
import { FLEET_DIVISOR, TICK_MS } from './state';
import { activityOf, alarmsOf, derive, normalizeFlat, type StatusModule, type StatusValues } from './status';
import { pruntTemperatureDecl } from './temperatures';
import { wsMessageSchema } from './wire';

/**
 * How the gateway shares one Prunt controller among every viewer (Node-safe, pure: the gateway
 * and the browser import it through `declaration.ts`). Prunt pushes everything live on one
 * socket, `/websocket/everything`: one upstream socket per machine, status ticks at the rate the
 * fastest viewer asks for, each browser throttled to its own.
 */

/** The divisor a Prunt socket starts with (prunt-web_server.adb `WebSocket_Open`): 20 ticks of 50 ms. */
export const DEFAULT_DIVISOR = FLEET_DIVISOR;
/** Prunt keeps the divisor in a `mod 2**32` type: a larger number is refused (its `'Value` raises). */
export const MAX_DIVISOR = 2 ** 32 - 1;
export const WATCH_EVERY_MS = 10_000;

/**
 * How long a page-open read is shared: the tabs of a shop that open at once (a reload, a wall
 * screen and a tablet) ask one question of the controller.
 */
export const PAGE_OPEN_WINDOW_MS = 2000;

/**
 * The reads every page makes when it opens (and after a server restart): the status schema and
 * the update check (module API `/update-check`, 2025 flat API `/update_check`), without a query.
 * Shared for PAGE_OPEN_WINDOW_MS: N tabs opened together make one request. The schema changes
 * only with a restart of Prunt's server, which takes longer than the window; a restart from the
 * console (`/reload-server`) is a command, and a command drops the machine's kept answers
 * (gateway/upstream-http.ts).
 */
const PAGE_OPEN_READS = new Set(['/status/schema', '/update-check', '/update_check']);

/**
 * Nothing else is shared. The console polls no read: status, logs and command progress come by
 * the socket. Its other reads are on demand (the uploads list, files, the configuration) or
 * follow a command: `GET /status/values` right after a pause must show the pause, so it may not
 * be answered with a read from just before it; and `GET /config/values` right after a save must
 * show the save.
 */
export function pruntShareRead(path: string, query: URLSearchParams): number | null {
  if ([...query.keys()].length > 0) return null;
  return PAGE_OPEN_READS.has(path) ? PAGE_OPEN_WINDOW_MS : null;
}

// ---------------------------------------------------------------------------------- socket

/** The keys of a frame's JSON object; none for anything else (a broken or cut frame). */
function keysOf(frame: string): string[] {
  try {
    const v: unknown = JSON.parse(frame);
    return v && typeof v === 'object' && !Array.isArray(v) ? Object.keys(v) : [];
  } catch {
    return [];
  }
}

/**
 * - `Server_Start_Time` (sent on connect and when the server restarts; a browser refetches its
 *   schema when it changes): `latest` under 'start', replayed so a browser that joins learns it.
 * - `Status_Values` (module API) and `Status` (2025 flat API), the ticks: `latest` under
 *   'status', replayed (the current state for a browser that joins). A throttled browser skips
 *   ticks, as Prunt itself does with a divisor.
 * - `Log` and `Gcode_Command` (command progress): events, in order, never dropped. Not replayed:
 *   a browser would log old lines as new ones, and command progress belongs to the browser that
 *   is waiting for it, which was connected.
 * - Anything else (a kind this console does not know, a broken frame): an event, so nothing is
 *   lost and nothing broken is replayed.
 */
export function classifyPruntFrame(frame: string): FrameClass {
  const keys = keysOf(frame);
  if (keys.includes('Server_Start_Time')) return { kind: 'latest', key: 'start', replay: true };
  if (keys.includes('Status_Values') || keys.includes('Status'))
    return { kind: 'latest', key: 'status', replay: true };
  return { kind: 'event', replay: false };
}

/**
 * The browser's only frame: the tick divisor as plain decimal digits (session.ts `sendDivisor`,
 * `String(divisor)`), a positive integer that Prunt's `mod 2**32` type can hold. It wants a tick
 * every N × 50 ms. Anything else is dropped.
 */
export function pruntFromBrowser(frame: string): { rateMs: number } | null {
  const m = /^\s*(\d{1,10})\s*$/.exec(frame);
  if (!m) return null;
  const n = Number(m[1]);
  if (n < 1 || n > MAX_DIVISOR) return null;
  return { rateMs: n * TICK_MS };
}

/** The divisor to ask Prunt for when the fastest viewer wants a tick every `rateMs` (never slower). */
export function pruntUpstreamRate(rateMs: number): string {
  if (Number.isNaN(rateMs)) return String(DEFAULT_DIVISOR);
  const n = Math.floor(rateMs / TICK_MS);
  return String(Math.min(MAX_DIVISOR, Math.max(1, n)));
}

export const pruntStream: FanoutStreamDecl = {
  kind: 'fanout',
  path: '/websocket/everything',
  matches: (path) => path === '/websocket/everything',
  graceMs: 10_000,
  classify: classifyPruntFrame,
  fromBrowser: pruntFromBrowser,
  upstreamRate: pruntUpstreamRate,
  /** Without a divisor Prunt sends every 20th tick: once a second. */
  defaultRateMs: DEFAULT_DIVISOR * TICK_MS,
};

// ---------------------------------------------------------------------------------- watch

/** The status model `derive` needs, from the values themselves (the watch has no schema). */
function modelOf(values: StatusValues): StatusModule[] {
  return Object.entries(values).map(([name, groups]) => ({
    name,
    groups: Object.entries(groups).map(([g, entries]) => ({
      name: g,
      entries: Object.keys(entries).map((n) => ({
        module: name,
        group: g,
        name: n,
        kind: '',
        unit: '',
        description: '',
        condition: '',
      })),
    })),
  }));
}

/**
 * A socket frame → the summary, with the console's own reading (status.ts): a tick says the whole
 * state (the file being run, paused, startup, a server exception), so it gives all three fields;
 * every other frame says nothing (null). Garbage: null, never a throw.
 */
export function readPruntFrame(frame: string): Partial<WatchSummary> | null {
  let json: unknown;
  try {
    json = JSON.parse(frame);
  } catch {
    return null;
  }
  const r = wsMessageSchema.safeParse(json);
  if (!r.success || r.data.type !== 'tick') return null;
  const m = r.data;
  const values = m.api === 'module' ? m.values : normalizeFlat(m.values);
  const exception = m.api === 'module' ? m.exception : null;
  const d = derive(modelOf(values), values);
  const { activity } = activityOf(d, m.startup, exception);
  const alarms = alarmsOf(m.startup, exception, () => 0);
  return {
    state: watchStateOf(activity),
    alarm: alarms.length ? alarms.map((a) => a.message).join('; ') : null,
    job: d.fileName ? d.fileName.replace(/^uploads\//, '') : null,
    alarms: watchAlarmsOf(alarms),
  };
}

/**
 * The watch keeps the shared socket open and reads its ticks: Prunt has no cheaper status than
 * the socket (`GET /status/values` of the module API lacks the startup state and the server
 * exception). With no viewer, the socket runs at Prunt's default (a tick a second); `everyMs` is
 * how fresh the watch wants to be.
 */
export const pruntWatch: WatchDecl = {
  everyMs: WATCH_EVERY_MS,
  stream: { path: '/websocket/everything', read: readPruntFrame },
  temperatures: pruntTemperatureDecl,
};

export const pruntSharing: SharingHints = {
  shareRead: pruntShareRead,
  /**
   * Prunt answers every HTTP request with `Connection: close` (prunt-web_server.adb
   * `Send_Connection (Client, Persistent => False)`): nothing to keep.
   */
  keepAlive: false,
  /** One server task answers requests one after another (GNAT.Sockets.Server): more only queue there. */
  maxConcurrentReads: 2,
  streams: [pruntStream],
  watch: pruntWatch,
};
