import {
  type FanoutStreamDecl,
  type FrameClass,
  type SharingHints,
  type WatchDecl,
  type WatchNews,
  type WatchSummary,
  watchAlarmsOf,
  watchStateOf,
} from '../../fleet/contract';
import { xtoolAccess } from './access';
import { alarmForFrame, applyFrame, INITIAL_STATE, toActivity } from './state';
import { parseFrameText, parseXtoolError, workingStaSchema } from './wire';

/**
 * How the gateway shares one xTool D-series laser among every viewer (Node-safe, pure: the
 * gateway and the browser import it through `declaration.ts`). The laser is an ESP32 with room
 * for a few sockets: one status socket (:8081) for every browser, the two status polls answered
 * once per period, at most two reads at once, a new connection per request.
 */

/** The console polls this often while a job or frame is loaded or running (session.ts POLL_BUSY_MS). */
export const BUSY_POLL_MS = 3000;
/** How long a status answer is shared: a second less than the page's poll period. */
export const STATUS_WINDOW_MS = BUSY_POLL_MS - 1000;
/** The watch (the gateway itself, no page needed) polls every 10 s: the ESP32 is not loaded more. */
export const WATCH_EVERY_MS = 10_000;

/**
 * Shared reads (every viewer's tab asks the same of one ESP32):
 * - The status poll: `GET /system?action=get_working_sta`, then `GET /progress`, every 3 s. The
 *   window (STATUS_WINDOW_MS) is shorter than the period, which runs from the end of a page's poll
 *   to the start of its next: a page never gets its own last answer back as new (that would hide a
 *   fault for a whole period: the poll is the laser's liveness), and an answer is at most 2 s old.
 * - The settings (`/peripherystatus`, `/system?action=offset`, `/system?action=dotMode`), read
 *   once a minute by every tab (queries.ts SETTINGS_REFRESH_MS): one read a minute for all. A
 *   settings command must be seen at once: the gateway drops every kept answer of a machine when
 *   a command goes to it (gateway/upstream-http.ts), so the read after it goes to the laser.
 * - The identity at connect (`/getmachinetype`, `/getlaserpowertype`, `/getlaserpowerinfo`,
 *   `/system?action=version`, `mac`, `get_dev_name`): a minute (N tabs opening at once make one
 *   request each; a rename, `set_dev_name`, is a command and drops the kept answers).
 * Each only in exactly the form the console sends (the ESP32 matches paths exactly; a second
 * `action` could be read differently by the firmware than by the access policy). Nothing else is
 * shared: the SD card listing and every GET that acts (`/cnc/data`, `/system?action=set…`,
 * `/cmd`, `/read`, `/delete`: commands in access.ts).
 */
/** Every tab reads the settings once a minute (queries.ts SETTINGS_REFRESH_MS; not imported: React). */
const SETTINGS_REFRESH_MS = 60_000;

const SHARED_SYSTEM_ACTIONS: Readonly<Record<string, number>> = {
  get_working_sta: STATUS_WINDOW_MS,
  offset: SETTINGS_REFRESH_MS,
  dotMode: SETTINGS_REFRESH_MS,
  version: SETTINGS_REFRESH_MS,
  mac: SETTINGS_REFRESH_MS,
  get_dev_name: SETTINGS_REFRESH_MS,
};
const SHARED_PATHS: Readonly<Record<string, number>> = {
  '/progress': STATUS_WINDOW_MS,
  '/peripherystatus': SETTINGS_REFRESH_MS,
  '/getmachinetype': SETTINGS_REFRESH_MS,
  '/getlaserpowertype': SETTINGS_REFRESH_MS,
  '/getlaserpowerinfo': SETTINGS_REFRESH_MS,
};

export function xtoolShareRead(path: string, query: URLSearchParams): number | null {
  const params = [...query];
  let window: number | null = null;
  if (params.length === 0) window = SHARED_PATHS[path] ?? null;
  const action = query.get('action');
  if (
    path === '/system' &&
    params.length === 1 &&
    action !== null &&
    Object.hasOwn(SHARED_SYSTEM_ACTIONS, action)
  )
    window = SHARED_SYSTEM_ACTIONS[action] ?? null;
  if (window === null) return null;
  const d = xtoolAccess({ method: 'GET', path, query });
  return d.command || d.role !== 'viewer' ? null : window;
}

// ---------------------------------------------------------------------------------- :8081

/**
 * A frame of the status socket. The socket says nothing on connect and nothing while the state
 * stays the same, so a browser that joins needs the last state frame: state frames (`ok:IDLE`,
 * `ok:WORKING_*`, `ok:PAUSING`, `WORK_STOPPED`/`WORK_STOPED`) are `latest` under one key, replayed.
 *
 * `ok:ERROR` and `err:*Check` (flame, tilt, movement, limit) raise alarms in the browser: they
 * are events, never dropped behind a later `ok:IDLE`. Not replayed (decision): the frames carry no
 * time and the laser has no alarm to acknowledge, so a browser that opens the page later would
 * raise "FLAME DETECTED — go to the laser now" as new, hours after the fact and for every viewer
 * until the next alarm; the gateway's watch records the alarm when it happens, and a browser that
 * was connected gets it in order. Unknown frames are events too (the browser logs them).
 */
export function classifyXtoolFrame(frame: string): FrameClass {
  const f = parseFrameText(frame);
  if (f.kind === 'state' || f.kind === 'stopped') return { kind: 'latest', key: 'state', replay: true };
  return { kind: 'event', replay: false };
}

export const xtoolStatusStream: FanoutStreamDecl = {
  kind: 'fanout',
  // The browser opens `/machines/<id>/`: the root of the laser's :8081 (declaration.ts).
  path: '/',
  matches: (path) => path === '/',
  // A page reload or going from the fleet to a machine page keeps the ESP32's socket.
  graceMs: 10_000,
  classify: classifyXtoolFrame,
  // A read-only channel: the laser takes no frame from a client, the browser sends none.
  fromBrowser: () => null,
};

// ---------------------------------------------------------------------------------- watch

/**
 * `GET /system?action=get_working_sta` → the summary: "0" idle; "1" (started by the API) and "2"
 * (started with the button, or loaded and waiting for it: the two look the same) running, as the
 * console counts "2" with nothing else known (README, "Activity"). The answer names no job and no
 * alarm: alarms come by the socket (`readXtoolFrame`), and this poll clears them once the laser
 * says where it is (the D-series has no alarm state: a sensor aborts the job and the laser is idle).
 */
export function readWorkingSta(status: number, body: string, known?: WatchSummary): WatchNews | Error {
  if (status < 200 || status > 299) return new Error(`get_working_sta answered ${status}`);
  let json: unknown;
  try {
    json = JSON.parse(body);
  } catch {
    return new Error(`get_working_sta: not JSON (${body.trim().slice(0, 60)})`);
  }
  const vendor = parseXtoolError(status, json, body);
  if (vendor) return new Error(`get_working_sta: ${vendor.message}`);
  const p = workingStaSchema.safeParse(json);
  if (!p.success) return new Error('get_working_sta: no "working" in the answer');
  // "1"/"2" is a job running or paused (the answer cannot tell them apart): a pause the socket
  // said (ok:PAUSING) stays a pause until a frame says otherwise.
  const busy = known?.state === 'paused' ? 'paused' : 'running';
  const state = p.data.code === 'idle' ? 'idle' : p.data.code === 'unknown' ? 'unknown' : busy;
  // Idle: no job. Running: the answer cannot name it, so it says nothing of it, and the name a
  // frame gave (the loaded /tmp.gcode, started with the button) stays the job's (issue 33, 6).
  return state === 'idle'
    ? { state, alarm: null, job: null, alarms: [] }
    : { state, alarm: null, alarms: [] };
}

/**
 * A socket frame → what it says: the state (through the console's own state machine) and, for
 * `ok:ERROR` and `err:*Check`, the alarm in the console's words. A state frame leaves the alarm
 * alone (the poll clears it); unknown frames say nothing.
 */
export function readXtoolFrame(frame: string): WatchNews | null {
  const f = parseFrameText(frame);
  if (f.kind === 'unknown') return null;
  const state = watchStateOf(toActivity(applyFrame(INITIAL_STATE, f).state));
  const alarm = alarmForFrame(f, 0);
  // A job loaded or run by software is the uploaded /tmp.gcode (model.ts `jobNameAfter`): its name
  // for the server's job record and history, as the machine page says it.
  const job =
    f.kind === 'state' && (f.state === 'job-loaded' || f.state === 'running-online')
      ? 'tmp.gcode'
      : undefined;
  // Idle: nothing loaded any more (a loaded job says so in its own frame, ok:WORKING_ONLINE_READY).
  const named = job ? { job } : f.kind === 'state' && f.state === 'idle' ? { job: null } : {};
  return alarm
    ? { state, alarm: alarm.message, raise: watchAlarmsOf([alarm]), ...named }
    : { state, ...named };
}

/**
 * The watch: the socket kept open (an alarm arrives the moment the laser sends it; a flame is the
 * reason to watch a laser at all), and the working state polled every 10 s, the console's own idle
 * period: the socket sends nothing on connect and has no heartbeat, so only a poll tells the state
 * and that the laser still answers. A faster poll would only load the ESP32. The poll's path
 * carries its query (`pathAndQuery`, as `UpstreamRequest` takes it).
 */
export const xtoolWatch: WatchDecl = {
  everyMs: WATCH_EVERY_MS,
  poll: { path: '/system?action=get_working_sta', read: readWorkingSta },
  stream: { path: '/', read: readXtoolFrame },
};

export const xtoolSharing: SharingHints = {
  shareRead: xtoolShareRead,
  /**
   * The ESP32 has room for a few sockets: a kept-alive idle connection would hold one of them
   * from the vendor app and the laser's own needs. One connection per request (README).
   */
  keepAlive: false,
  /** An ESP32 with room for a few sockets; the console itself never sends it two at once. */
  maxConcurrentReads: 2,
  streams: [xtoolStatusStream],
  watch: xtoolWatch,
};
