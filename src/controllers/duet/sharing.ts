import {
  type ModelStreamDecl,
  type SharingHints,
  type WatchDecl,
  type WatchAlarm,
  type WatchNews,
  type WatchSummary,
  watchAlarmsOf,
  watchStateOf,
} from '../../fleet/contract';
import { duetAccess } from './access';
import { baseName } from './client';
import { isRrPath, routeOf, type DuetApiState } from './gateway';
import {
  applyPatch,
  isObject,
  MAX_DEPTH,
  nestsDeeper,
  patchBetween,
  takeFullModel,
  type Json,
  type JsonObject,
} from './patch';
import { activityOf, alarmsOf, jobSummary } from './snapshot';
import { duetTemperatureDecl } from './temperatures';
import { machineStatus, objectModelSchema } from './wire';

/**
 * How the gateway shares one Duet (DSF) among every viewer (Node-safe, pure: the gateway and the
 * browser import it through `declaration.ts`). DSF is ASP.NET Core on an SBC: one `WS /machine`
 * per machine carries the object model to every browser (the gateway keeps the merged model and
 * gives each browser the full model, then patches at its own pace); the HTTP reads the console
 * polls are shared; the watch keeps the socket and reads the model now and then.
 */

/** The browser polls the model this often while its socket is down (session.ts POLL_EVERY_MS). */
export const MODEL_POLL_MS = 2000;
/** The browser's keep-alive of the DSF session while its socket is down (session.ts NOOP_EVERY_MS). */
export const NOOP_MS = 4000;
/** The browser pings a silent socket after this long (session.ts PING_AFTER_MS): the gateway does the same upstream. */
export const UPSTREAM_PING_MS = 2000;
/** The watch reads the whole model this often (see `duetWatch`). */
export const WATCH_EVERY_MS = 10_000;

/** A GET the browser polls, exactly as it sends it (routes compare as ASP.NET does: `routeOf`). */
const POLLED: Record<string, number> = {
  '/machine/model': MODEL_POLL_MS,
  '/machine/noop': NOOP_MS,
};

/**
 * `GET /machine/model` (the fallback poll while the browser's socket is down, every 2 s) and
 * `GET /machine/noop` (the session keep-alive beside it, every 4 s) are shared, with no query
 * (the browser sends none). Nothing else is polled by HTTP: listings, file info, downloads and the
 * height map are on-demand reads, and `connect`/`disconnect` are the held session's (never
 * shared: a password may ride on connect). Anything the access policy calls a command is never
 * shared (a GET never is one on DSF today, but the policy is asked anyway).
 */
export function duetShareRead(path: string, query: URLSearchParams): number | null {
  const window = POLLED[routeOf(path)];
  if (window === undefined || [...query.keys()].length > 0) return null;
  if (duetAccess({ method: 'GET', path, query }).command) return null;
  return window;
}

// ---------------------------------------------------------------------------------- WS /machine

function parseObject(frame: string, what: string): JsonObject | Error {
  let parsed: unknown;
  try {
    parsed = JSON.parse(frame);
  } catch {
    return new Error(`WS /machine: ${what} that is not JSON (${frame.trim().slice(0, 60)})`);
  }
  return isObject(parsed) ? parsed : new Error(`WS /machine: ${what} that is not a JSON object`);
}

const isPong = (frame: string): boolean => frame.trim() === 'PONG';

/**
 * A browser's frame, as DSF's WebSocketController reads it: the frame is split at CR and LF, each
 * line must be exactly `OK` or `PING` (or blank); anything else makes DSF close the socket (1003),
 * so the gateway drops it. The browser sends `OK\n` after each frame and `PING\n` when the socket
 * was silent (session.ts); DSF answers `PONG\n`, and so does the gateway (ingest.ts accepts it
 * trimmed). A frame mixing both is dropped (the browser never sends one).
 */
export function duetFromBrowser(frame: string): { ack: true } | { reply: string } | null {
  const lines = frame.split(/[\r\n]/).filter((l) => l.trim() !== '');
  if (lines.length === 0) return null;
  if (lines.every((l) => l === 'OK')) return { ack: true };
  if (lines.every((l) => l === 'PING')) return { reply: 'PONG\n' };
  return null;
}

export const duetModelStream: ModelStreamDecl = {
  kind: 'model',
  path: '/machine',
  matches: (path) => routeOf(path) === '/machine',
  // DSF registers a user session per socket (sbc.dsf.userSessions): a page reload should not
  // close one and open another.
  graceMs: 10_000,
  full(frame) {
    const obj = parseObject(frame, 'a first frame');
    if (obj instanceof Error) return obj;
    // The messages of the first frame are DSF's pending ones at that moment: events, not model.
    const r = takeFullModel(obj);
    return r.refused === null ? r.model : new Error(`WS /machine: ${r.refused}`);
  },
  apply(model, frame) {
    // The gateway's own keep-alive answer, should it come here: nothing changes.
    if (isPong(frame)) return { model, events: [] };
    const patch = parseObject(frame, 'a patch');
    if (patch instanceof Error) return patch;
    const r = applyPatch(model, patch);
    if (r.refused !== null) return new Error(`WS /machine: ${r.refused}`);
    return { model: r.model, events: r.messages };
  },
  diff: (from, to, events) => JSON.stringify(patchBetween(from, to, events)),
  first: (model) => JSON.stringify(model),
  ack: 'OK\n',
  fromBrowser: duetFromBrowser,
  /**
   * DSF answers `PING\n` with `PONG\n` (WebSocketController). Its server-side keep-alive keeps
   * an idle socket open (ASP.NET WebSocket keep-alive), so the ping is not needed to keep it: it
   * is how a powered-off machine is noticed (the document: "useful for clients to detect
   * unexpected connection aborts"). Browsers' PINGs are answered by the gateway now, so the
   * gateway notices for them: a PING after 2 s of silence, and the Duet is gone after 4.5 s
   * without any frame (streams.ts: every page socket closes, within the issue's 5 s).
   */
  ping: { frame: 'PING\n', everyMs: UPSTREAM_PING_MS, isPong },
};

// ---------------------------------------------------------------------------------- watch

/** A whole object model (`GET /machine/model`, the socket's first frame) → the summary. */
export function summaryOfModel(raw: JsonObject): WatchSummary | Error {
  const p = objectModelSchema.safeParse(raw);
  if (!p.success) {
    const i = p.error.issues[0];
    return new Error(`Object model: ${i ? `${i.path.join('.')}: ${i.message}` : 'invalid'}`);
  }
  const m = p.data;
  const alarms = alarmsOf(m, () => 0);
  const job = jobSummary(m);
  return {
    state: watchStateOf(activityOf(m.state.status)),
    alarm: alarms.length ? alarms.map((a) => a.message).join('; ') : null,
    job: job?.name ?? null,
    alarms: watchAlarmsOf(alarms),
    progress: job?.progress ?? null,
  };
}

function child(o: Json | undefined, key: string): Json | undefined {
  return isObject(o) && Object.hasOwn(o, key) ? o[key] : undefined;
}

/**
 * What one patch says for certain: a new `state.status` (and the alarm of `halted` or
 * `disconnected`), a heater that went into fault, a new job file. It never clears an alarm: a
 * patch shows only what changed, so it cannot tell that no other alarm is left (the watch's next
 * model read does, within `WATCH_EVERY_MS`).
 */
function newsOfPatch(patch: JsonObject): WatchNews | null {
  const out: WatchNews = {};
  const alarms: WatchAlarm[] = [];
  const status = child(child(patch, 'state'), 'status');
  if (status !== undefined) {
    const s = machineStatus.safeParse(status);
    if (s.success) {
      out.state = watchStateOf(activityOf(s.data));
      // The same keys and words as the page's alarms (snapshot.ts alarmsOf).
      if (s.data === 'halted')
        alarms.push({ key: 'halted', severity: 'critical', text: 'Emergency stop: the machine is halted' });
      if (s.data === 'disconnected')
        alarms.push({
          key: 'disconnected',
          severity: 'critical',
          text: 'DSF has lost the connection to the firmware board',
        });
    }
  }
  const heaters = child(child(patch, 'heat'), 'heaters');
  if (Array.isArray(heaters)) {
    heaters.forEach((h, i) => {
      if (child(h, 'state') === 'fault')
        alarms.push({ key: `heater-${i}-fault`, severity: 'critical', text: `Heater fault: heater ${i}` });
    });
  }
  if (alarms.length) {
    out.state = 'alarm';
    out.alarm = alarms.map((a) => a.text).join('; ');
    out.raise = alarms;
  }
  const fileName = child(child(child(patch, 'job'), 'file'), 'fileName');
  if (fileName === null) out.job = null;
  else if (typeof fileName === 'string') out.job = fileName ? baseName(fileName) : null;
  return Object.keys(out).length ? out : null;
}

/** The top-level parts every whole model has (model_geminiv2.json, model_virgin.json). */
const WHOLE_PARTS = ['boards', 'directories', 'fans', 'heat', 'job', 'move', 'state', 'tools', 'volumes'];

/**
 * A frame that is a whole model (a socket's first frame) rather than a patch: every part is
 * there and every heater is whole (a patch sends `{}` for heaters it does not change).
 */
function looksWhole(obj: JsonObject): boolean {
  if (!WHOLE_PARTS.every((k) => Object.hasOwn(obj, k))) return false;
  const heaters = child(child(obj, 'heat'), 'heaters');
  return (
    child(child(obj, 'state'), 'status') !== undefined &&
    Array.isArray(heaters) &&
    heaters.every((h) => h === null || child(h, 'state') !== undefined)
  );
}

/**
 * A frame of the shared `WS /machine`: a full model (a socket's first frame: everything) or a
 * patch (what it says for certain). PONG, garbage and patches without news: null. Never throws.
 */
export function readModelFrame(frame: string): WatchNews | null {
  const obj = parseObject(frame, 'a frame');
  if (obj instanceof Error || nestsDeeper(obj, MAX_DEPTH)) return null;
  if (looksWhole(obj)) {
    const s = summaryOfModel(obj);
    if (!(s instanceof Error)) return s;
  }
  return newsOfPatch(obj);
}

/**
 * The watch. DSF has no cheap state endpoint (`GET /machine/model` and `/machine/status` are the
 * whole model, about 25 KB; the standalone `rr_model?key=` is not served in SBC mode), and its
 * socket sends only what changed. So both:
 * - `stream` keeps the shared `WS /machine` open: news arrives at once (a halt, a heater fault,
 *   a new job), and the open socket keeps the gateway's DSF session alive (DSF drops a session 8 s
 *   after its last request unless a socket is open), so the poll below never meets an expired key;
 * - `poll` reads the whole model every 10 s: the full truth, which also clears alarms (a patch
 *   cannot). 25 KB every 10 s is nothing to an SBC; a printer's own firmware halts on heater
 *   faults, so 10 s is enough for a record.
 */
export const duetWatch: WatchDecl = {
  everyMs: WATCH_EVERY_MS,
  poll: {
    path: '/machine/model',
    read(status, body) {
      if (status < 200 || status > 299) return new Error(`GET /machine/model answered ${status}`);
      const obj = parseObject(body, 'an answer');
      if (obj instanceof Error) return new Error(obj.message.replace('WS /machine', 'GET /machine/model'));
      const r = takeFullModel(obj);
      return r.refused === null ? summaryOfModel(r.model) : new Error(`GET /machine/model: ${r.refused}`);
    },
  },
  stream: { path: '/machine', read: readModelFrame },
  temperatures: duetTemperatureDecl,
};

export const duetSharing: SharingHints = {
  shareRead: duetShareRead,
  /**
   * DSF is ASP.NET Core (Kestrel): HTTP/1.1 connections persist (Kestrel's keep-alive timeout is
   * two minutes), and Duet Web Control itself relies on that; a new TCP connection per poll on an
   * SBC is the waste.
   */
  keepAlive: true,
  /** Kestrel serves requests in parallel, but on an SBC (file info parses G-code files): four. */
  maxConcurrentReads: 4,
  streams: [duetModelStream],
  watch: duetWatch,
};

// ---------------------------------------------------------------------------------- standalone

/** The watch's read of a standalone board: the whole model, every part (`rr_model`, verbose). */
export const RRF_WATCH_PATH = '/rr_model?key=&flags=d99vno';
/** Identical `rr_model` reads of several viewers within this window: one upstream. */
export const RRF_SHARE_MS = 1000;
/**
 * The watch of a standalone board: `rr_model` polled every 10 s (no socket on RepRapFirmware
 * standalone; the gateway's keep-alive holds the session between polls).
 */
export const rrfWatch: WatchDecl = {
  everyMs: WATCH_EVERY_MS,
  poll: {
    path: RRF_WATCH_PATH,
    read(status, body) {
      if (status < 200 || status > 299) return new Error(`GET /rr_model answered ${status}`);
      const obj = parseObject(body, 'an answer');
      if (obj instanceof Error) return new Error(obj.message.replace('WS /machine', 'GET /rr_model'));
      if (nestsDeeper(obj, MAX_DEPTH))
        return new Error(`GET /rr_model: nested deeper than ${MAX_DEPTH} levels`);
      const result = obj['result'];
      if (!isObject(result)) return new Error('GET /rr_model: no model in "result"');
      const { seqs: _seqs, ...model } = result;
      const r = takeFullModel(model);
      return r.refused === null ? summaryOfModel(r.model) : new Error(`GET /rr_model: ${r.refused}`);
    },
  },
  temperatures: duetTemperatureDecl,
};

/**
 * Reads of a standalone board several viewers may share: the model polls. (`rr_reply` never
 * reaches the board from a browser: the gateway answers it, `replies.ts`.)
 */
export function rrfShareRead(path: string, query: URLSearchParams): number | null {
  if (routeOf(path) !== '/rr_model') return null;
  if (duetAccess({ method: 'GET', path, query }).command) return null;
  return RRF_SHARE_MS;
}

/**
 * The sharing hints of ONE Duet, by the API its held session learned (`state`, DSF until known).
 * A standalone board has few HTTP connections (RepRapFirmware serves a handful of responders, and
 * a Duet 2 WiFi fewer): at most two reads at once (the page's poll is one at a time, a file read
 * beside it), no kept TCP connections (RRF closes them), no sockets, and the `rr_model` watch.
 */
export function duetSharingFor(state: DuetApiState, base: SharingHints = duetSharing): SharingHints {
  const standalone = () => state.api === 'standalone';
  return {
    shareRead: (path, query) =>
      isRrPath(path) ? rrfShareRead(path, query) : (base.shareRead?.(path, query) ?? null),
    get keepAlive() {
      return standalone() ? false : base.keepAlive;
    },
    get maxConcurrentReads() {
      return standalone() ? 2 : base.maxConcurrentReads;
    },
    get streams() {
      return standalone() ? [] : base.streams;
    },
    watch: watchFor(state, base.watch),
  };
}

/**
 * One machine's watch, following what its session learned (`state.api`, read at every poll): the
 * `rr_model` poll of a standalone board, DSF's model poll and socket, and, while the API is not
 * known yet, DSF's poll without the socket: that first read opens the gateway's session, whose
 * probe learns the API, and the watch reads again at once with the poll of the API it learned
 * (gateway/watch.ts), then holds DSF's socket if it is DSF. The interval is the family's
 * (`base.everyMs`) for both.
 */
function watchFor(state: DuetApiState, base: WatchDecl | undefined): WatchDecl | undefined {
  if (!base) return undefined;
  return {
    get everyMs() {
      return base.everyMs;
    },
    get poll() {
      return state.api === 'standalone' ? rrfWatch.poll : base.poll;
    },
    get stream() {
      return state.api === 'dsf' ? base.stream : undefined;
    },
    temperatures: base.temperatures,
  };
}
