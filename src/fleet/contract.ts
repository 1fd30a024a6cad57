import type { ComponentType, ReactNode } from 'react';
import type { StoreApi } from 'zustand/vanilla';
import type { AccessPolicy, BodyNeeded } from './access';
import type { CommandDecl, CommandRunner } from './commands';
import { LinkError } from './errors';
import { backoffDelay, type Visibility } from './link';
import type { MachineQueries } from './kernel/query';
import type { MachineLog } from './log';
import type { SimulatorFactory } from './sim';
import type {
  Activity,
  Alarm,
  AlarmSeverity,
  LinkState,
  MachineInfo,
  MachineApi,
  MachineKind,
  MachineSnapshot,
  Role,
} from './types';

/**
 * The controller contract: what a family module provides. A family lives in one folder under
 * `src/controllers/<kind>/` and is listed once in `src/controllers/index.ts` (browser: sessions
 * and views) and once in `src/controllers/families.ts` (Node-safe: access rules, gateway hints,
 * simulator) — the gateway must not load React views, hence the two lists.
 */

/**
 * Node-safe declaration of a family (`<kind>/declaration.ts`): used by the gateway, `npm run sim`
 * and the browser alike. No simulator: the browser never loads one (simulated machines are
 * answered by the gateway), so the production bundle carries none.
 */
export interface FamilyDeclaration {
  kind: MachineKind;
  /** "xTool D-series" */
  label: string;
  /** Which requests need which role, which are commands (audited). */
  access: AccessPolicy;
  /** Requests whose body the gateway must read to classify them. */
  accessNeedsBody?: BodyNeeded;
  /** The most of such a body the gateway reads (bytes), when more than its default (g2core's job upload). */
  accessBodyLimit?: (method: string, path: string) => number | undefined;
  gateway?: GatewayHints;
  /**
   * The family's job commands by what they do (ids of its declared commands): the job control row,
   * the kiosk and the production history (which command started, paused or stopped a job) read
   * them from here. A family whose API commands nothing (TouchCut) declares none.
   */
  jobs?: JobCommandIds;
}

/** A family's job commands by what they do (`X-Shopdeck-Command` ids, `<kind>.<command>`). */
export interface JobCommandIds {
  /** Starts a job from a file (the history attributes the job to who sent it). */
  start?: string;
  pause: string;
  resume: string;
  /** The job's stop (cancel, kill). */
  stop: string;
  /** The machine's emergency stop, where the console may send one (also ends the job). */
  estop?: string;
}

/** A control of the job control row (src/app/kiosk/JobControls.tsx). */
export type JobControlKind = 'pause' | 'resume' | 'stop' | 'estop';

/**
 * A family's manifest (`<kind>/manifest.ts`): what the console knows of the family before its code
 * loads. Plain data, small and Node-safe (no React, no views: loaders only): the shell carries
 * every family's, and the family's declaration takes its kind, label and job commands from it.
 * `src/controllers/index.ts` lists each family once, by its manifest and its page module.
 */
export interface FamilyManifest {
  kind: MachineKind;
  /** "xTool D-series" */
  label: string;
  /** The family's job commands by what they do (see `FamilyDeclaration.jobs`). */
  jobs?: JobCommandIds;
  /** The job control row's words of this family (with `jobs`; without it, state and progress only). */
  kiosk?: KioskManifest;
  /** Family-level pages outside any machine, routed at `/<kind>/<path>` (their code loads when shown). */
  pages?: FamilyPageManifest[];
  /** What the production history keeps of this family beyond jobs and states. */
  history?: {
    /** The name of the daily statistics the console server imports from its controllers. */
    statisticsDays?: string;
  };
}

export interface KioskManifest {
  /** The firmware's own term for each control (the subtitle under the shared word). */
  terms: Partial<Record<JobControlKind, string>>;
  /** What dismissing the job stop's question keeps ("Keep printing"). */
  keep: string;
  /**
   * A view of the family's own shown below the controls in the kiosk: by convention its
   * `views/KioskExtra.tsx` (the bundle report looks for it there), a chunk of its own.
   */
  extra?: () => Promise<{ KioskExtra: (props: TabProps<never>) => ReactNode }>;
}

export interface FamilyPageManifest {
  path: string;
  label: string;
  load: () => Promise<() => ReactNode>;
}

/** A family as Node sees it (`<kind>/family.ts`): its declaration and its simulator. */
export interface FamilyDescriptor extends FamilyDeclaration {
  createSimulator: SimulatorFactory;
}

export interface GatewaySecrets {
  apiKey?: string;
  password?: string;
}

export interface GatewayHints {
  /** WebSocket port on the controller's host when the machine has no `wsUrl` (xTool: 8081). */
  defaultWsPort?: number;
  /**
   * Answers the console shows as images (thumbnails, screenshots, help pictures): only these keep a
   * raster image type; every other image answer is served as a download (gateway/answer-headers.ts).
   */
  imageAnswer?: (path: string) => boolean;
  /**
   * Add secrets to a forwarded request. `headers` and `query` are mutable copies; never put a
   * secret anywhere it could be echoed back to the browser.
   */
  injectSecrets?: (
    req: { method: string; path: string; headers: Record<string, string>; query: URLSearchParams },
    secrets: GatewaySecrets,
  ) => void;
  /**
   * The gateway holds this controller's session (gateway/held-session.ts): it opens it, keeps the
   * key, renews and keeps it alive, and adds it on the way out; the browser never sees the key.
   */
  session?: HeldSessionHooks;
  /**
   * How the gateway shares this controller among every viewer (gateway/upstream-http.ts,
   * gateway/streams.ts, gateway/watch.ts): one upstream per machine whatever the number of tabs.
   */
  sharing?: SharingHints;
  /**
   * Controller sockets bridged one to one (each browser socket its own upstream socket, frames
   * passed both ways), for a socket that cannot be shared. None of the five families has one:
   * every socket of theirs is a shared stream (`sharing.streams`). A WebSocket path that is
   * neither is refused (404) before anything reaches the controller. At most `maxPerMachine`
   * such upstream sockets are open for one machine (more: 503).
   */
  bridgedSockets?: { matches(path: string): boolean; maxPerMachine: number };
  /**
   * The session hooks and sharing hints of ONE machine (the gateway asks once per machine and
   * keeps them), for a family whose controllers speak more than one API: which one is learned
   * when the session is opened (Duet: DSF or standalone `rr_*`, the held session's probe) or told
   * by the machines file's `api`. Without it, `session` and `sharing` serve every machine.
   */
  forMachine?(m: { id: string; api?: MachineApi }): { session?: HeldSessionHooks; sharing?: SharingHints };
}

/**
 * A family's declaration of how its controller is shared (`<kind>/sharing.ts`, Node-safe, pure).
 * The mechanism is the gateway's, once; the family only says what is safe for its controller.
 */
export interface SharingHints {
  /**
   * Identical reads (GET, same path and query, not a command) that may be answered from one
   * upstream request: the window in ms within which an answer is given again (the family's poll
   * period for that path), or null: never shared. Commands are never shared, cached or retried.
   */
  shareRead?(path: string, query: URLSearchParams): number | null;
  /** Keep TCP connections to the controller open between requests (its server allows it). */
  keepAlive: boolean;
  /**
   * At most this many reads upstream at once for one machine; more wait in a queue (bounded).
   * Commands never wait behind reads: they go at once, in the order they arrived.
   */
  maxConcurrentReads: number;
  /** The controller's WebSockets that are shared: one upstream socket per machine and path. */
  streams?: SharedStreamDecl[];
  /** The slow watch the gateway keeps on the machine with no viewer (state and alarms). */
  watch?: WatchDecl;
}

/** How a frame of a shared stream travels to browsers. */
export type FrameClass =
  /**
   * A state frame: a newer one with the same key makes an undelivered older one pointless. A
   * slow or throttled browser gets only the latest of each key; a browser that joins later is
   * first given the latest one of each key whose `replay` is true.
   */
  | { kind: 'latest'; key: string; replay: boolean }
  /**
   * An event (a log line, an alarm): delivered in order, never dropped; a browser too slow for
   * them is closed (1013) and reconnects. `replay`: kept (the last few) for browsers that join later.
   */
  | { kind: 'event'; replay?: boolean };

interface StreamDeclBase {
  /**
   * The socket's canonical path on the controller ("/websocket/everything", "/" for xTool's
   * :8081): what goes upstream and what names the one shared socket, whichever spelling matched.
   */
  path: string;
  /** Whether a browser's (canonical) path is this socket ("/machine" in any spelling DSF takes). */
  matches(path: string): boolean;
  /**
   * The query parameters that choose a different stream on the controller, each with the closed
   * set of values it may take (none: the query is not part of the stream). Only these reach the
   * controller and tell shared sockets apart; any other parameter a browser sends is dropped, and
   * a declared one with another value is refused (400): a browser cannot open a socket per
   * query string.
   */
  query?: Readonly<Record<string, readonly string[]>>;
  /** The upstream socket stays this long after the last viewer left (unless the watch needs it). */
  graceMs: number;
}

/** A stream fanned out frame by frame (xTool :8081 frames, Prunt /websocket/everything). */
export interface FanoutStreamDecl extends StreamDeclBase {
  kind: 'fanout';
  classify(frame: string): FrameClass;
  /**
   * A browser's frame. `reply`: answered by the gateway to that browser alone; `rateMs`: the
   * browser wants `latest` frames at most this often (Prunt's divisor); null: dropped. Nothing a
   * browser sends reaches the shared upstream socket as it is.
   */
  fromBrowser?(frame: string): { reply: string } | { rateMs: number } | null;
  /** The frame sent upstream when the fastest `rateMs` any viewer wants changes (Prunt: the divisor). */
  upstreamRate?(rateMs: number): string;
  /** `rateMs` of a browser that asked for none. */
  defaultRateMs?: number;
}

/** A JSON value (model streams). */
export type JsonValue = null | boolean | number | string | JsonValue[] | { [key: string]: JsonValue };
export type JsonRecord = { [key: string]: JsonValue };

/**
 * A stream whose first frame is a full model and whose later frames are patches, each asked for
 * with an acknowledgement (Duet DSF `WS /machine`: full model, then `OK\n` → one patch; `PING\n`
 * → `PONG\n`). The gateway keeps the merged model; every browser gets the full model first and
 * patches after, each at its own pace (a slow browser gets one patch covering what it missed).
 */
export interface ModelStreamDecl extends StreamDeclBase {
  kind: 'model';
  /** The first frame: the full model, or why it is not one. */
  full(frame: string): JsonRecord | Error;
  /** A later frame applied to the model: the new model and the events it carried (Duet `messages`). */
  apply(model: JsonRecord, frame: string): { model: JsonRecord; events: JsonValue[] } | Error;
  /** A patch that takes `from` to `to` (with `events` carried), as one frame for a browser. */
  diff(from: JsonRecord, to: JsonRecord, events: JsonValue[]): string;
  /** A full model as the first frame for a browser. */
  first(model: JsonRecord): string;
  /** The frame that asks the controller for the next patch ("OK\n"). */
  ack: string;
  /** A browser's frame: its acknowledgement, a keep-alive with the answer to give, or null (dropped). */
  fromBrowser(frame: string): { ack: true } | { reply: string } | null;
  /** Keep-alive the gateway sends upstream when it has heard nothing for `everyMs` ("PING\n"). */
  ping?: { frame: string; everyMs: number; isPong(frame: string): boolean };
}

export type SharedStreamDecl = FanoutStreamDecl | ModelStreamDecl;

/** One alarm or message as the watch sees it (the alarm centre's record is made of these). */
export interface WatchAlarm {
  /** Stable per condition within a machine: the id of the console's own alarm (`xtool-flame`). */
  key: string;
  severity: AlarmSeverity;
  text: string;
  /** Blocks every page until acknowledged (an xTool flame): the family's `Alarm.blocking`. */
  blocking?: boolean;
}

/** The summary of a machine the gateway's watch keeps (state and alarms, for audit and history). */
export interface WatchSummary {
  /** `offline`: the watch cannot reach the machine (set by the watch itself, never by a family). */
  state: 'running' | 'paused' | 'idle' | 'alarm' | 'offline' | 'unknown';
  /** The alarm in words when one is active. */
  alarm: string | null;
  /** The job's file or program name when one is known. */
  job: string | null;
  /**
   * Every alarm and message active now, with its severity (the alarm centre). Absent: the family
   * did not say (the alarm centre keeps what it had).
   */
  alarms?: WatchAlarm[];
  /**
   * The keys a frame raised as a new event in this summary (a flame sent by the laser): a new
   * occurrence even while an acknowledged record of the same key is still open. Set by the watch.
   */
  raised?: string[];
  /**
   * How far the job is, 0..1, when the family's watch reads it (TouchCut, Duet); absent or null
   * when unknown. The job history keeps the last value a job had.
   */
  progress?: number | null;
  /**
   * Why the watch could not read the machine's answer (it answered, but not what the family reads:
   * a web page, a 404, a model that does not validate): the machine is "not read by the server",
   * its last reading no longer current. Null or absent: read. Set by the watch, never by a family.
   */
  unread?: string | null;
}

/**
 * The console server's record of a machine's job (issue 33): one per machine, kept by its watch
 * from the summaries it learns, the one source of every view's job facts (name, start, elapsed,
 * progress). Null while no job runs.
 */
export interface WatchJobRecord {
  /** The job's name as the server knows it (the summary's, kept once learnt); null: none known. */
  name: string | null;
  /** When the server first saw the job running or paused (ms, the server's clock). */
  startedAt: number;
  /**
   * Whether the server saw the job start (the machine was idle before): false when its first
   * reading already found it under way (the server started mid-job), so the job is older than that.
   */
  startSeen: boolean;
  /** 0..1, null when unknown. */
  progress: number | null;
}

/** What a frame of a watched stream says: part of a summary, and alarms it raised (a frame cannot clear). */
export type WatchNews = Partial<WatchSummary> & { raise?: WatchAlarm[] };

/** A family's own alarms (the same ids and words as on its pages) as the watch records them. */
export function watchAlarmsOf(alarms: readonly Alarm[]): WatchAlarm[] {
  return alarms.map((a) => ({
    key: a.id,
    severity: a.severity,
    text: a.message,
    ...(a.blocking ? { blocking: true } : {}),
  }));
}

/** A machine's activity as the watch records it (the same reading for every family). */
export function watchStateOf(a: Activity): WatchSummary['state'] {
  switch (a) {
    case 'running':
    case 'stopping':
      return 'running';
    case 'paused':
      return 'paused';
    case 'idle':
      return 'idle';
    case 'alarm':
    case 'error':
      return 'alarm';
    case 'offline':
    case 'unknown':
      return 'unknown';
  }
}

/**
 * The slow watch the gateway keeps on a machine nobody looks at: one read every `everyMs`
 * (`path`), or the shared stream kept open (`stream`: its path) and its frames read.
 */
export interface WatchDecl {
  everyMs: number;
  /** A read (GET `path`) whose answer `read` turns into a summary. */
  poll?: {
    path: string;
    /**
     * The summary, or the part the answer tells (a field left out: the watch keeps what it knew).
     * `known`: what the watch knew before this answer (an answer that cannot tell two states apart).
     */
    read(status: number, body: string, known?: WatchSummary): WatchSummary | WatchNews | Error;
  };
  /** A shared stream kept open while the watch runs; `read` turns its frames into summaries (null: no news). */
  stream?: { path: string; read(frame: string): WatchNews | null };
  /**
   * The temperatures the gateway keeps for the charts (gateway/temperatures.ts), read from what
   * the watch already reads (no read of their own): the poll's answer, a frame of the stream, or
   * the merged model of a model stream. Null: nothing read for certain. Never throws.
   */
  temperatures?: TemperatureDecl;
  /**
   * A second read made after a poll that found a job running or paused, when the poll's answer
   * names no job (g2core: the status report does not, `GET /job` does): its news (job name,
   * progress) join the summary; an error or null adds nothing.
   */
  jobPoll?: { path: string; read(status: number, body: string): WatchNews | null };
}

/** One sensor's reading as a family reads it (untrusted: the gateway checks and bounds it). */
export interface TemperatureReading {
  /** Stable per sensor within a machine (Duet: the heater index; Prunt: "group · name"). */
  key: string;
  /** What the chart calls it ("Bed", "Tool 0"). */
  name: string;
  /** °C; null: no sensor or no reading now. */
  value: number | null;
}

export interface TemperatureDecl {
  fromPoll?(path: string, status: number, body: string): TemperatureReading[] | null;
  fromFrame?(frame: string): TemperatureReading[] | null;
  fromModel?(model: JsonRecord): TemperatureReading[] | null;
}

/** An answer to a request the gateway made itself (held sessions). Header names are lower-case. */
export interface UpstreamAnswer {
  status: number;
  headers: Record<string, string>;
  body: string;
}

/** Sends one request of the gateway's own to the controller (or its simulator). */
export type UpstreamRequest = (
  method: string,
  pathAndQuery: string,
  headers?: Record<string, string>,
  body?: string,
) => Promise<UpstreamAnswer>;

/**
 * What a held session is opened with: the machine's configured password, or what a user typed into
 * the console's login form (a controller with user accounts, TouchCut, also takes a user name).
 */
export interface HeldCredentials {
  password: string;
  username?: string;
}

/** Requests the gateway answers itself from a held session. */
export type HeldIntercept =
  /**
   * The browser's "connect" or login: answered with the session's `answer` (the session is opened
   * first when there is none). `credentials`: what the user typed, when it is in the path or query;
   * `fromBody`: it is in the request body, which the gateway reads (bounded) and hands over with its
   * Content-Type. No credentials at all: the shared session's state as it is.
   */
  | {
      kind: 'open';
      credentials?: HeldCredentials;
      fromBody?: (body: string, contentType: string) => HeldCredentials;
    }
  /**
   * The browser's "disconnect" or logout, answered 204 locally. `end`: the shared session ends too,
   * and typed credentials are forgotten (a user login every viewer shared is logged out); otherwise
   * the shared session stays.
   */
  | { kind: 'close'; end?: boolean }
  /**
   * Sent to the controller by the gateway itself, with its key (and `injectSecrets`), never
   * retried; the answer goes through `exchanged` (a request whose answer carries a new key:
   * TouchCut's password change). The body is read (bounded) and sent as it came.
   */
  | { kind: 'exchange' }
  /** Answered as it is, never forwarded (a method the controller's login resource does not have). */
  | { kind: 'answer'; answer: UpstreamAnswer }
  /**
   * Answered by the family from requests of its own through the held session (`send`: the key
   * applied, never retried; an expired key is renewed for the next one). What a controller hands
   * out once for all its clients (RepRapFirmware's G-code replies) is fetched by the gateway alone
   * and given to each page as its own (the Duet family's `replies.ts`).
   */
  | { kind: 'relay'; run(send: HeldSend): Promise<UpstreamAnswer> };

/** One request of the gateway's own with the held session's key (a `relay` intercept). */
export type HeldSend = (
  method: string,
  path: string,
  query?: URLSearchParams,
  /**
   * `body`: the request body. `onData`: the answer's body is handed over as it comes instead of
   * kept (no size bound; the answer's `body` is then ""); returning false stops reading it.
   */
  opts?: { body?: string; onData?: (chunk: Uint8Array) => boolean },
) => Promise<UpstreamAnswer>;

export type HeldOpen =
  /** `key` null: the controller wants none (no password protection, no user logged in). `answer` never holds the key. */
  | { ok: true; key: string | null; answer: UpstreamAnswer }
  /** Refused (wrong password): the controller's answer, for the browser as it is. */
  | { ok: false; answer: UpstreamAnswer };

/** A family's declaration that the gateway holds the controller's session (Node-safe, pure). */
export interface HeldSessionHooks {
  /** Requests the gateway answers itself instead of forwarding them, or null. */
  intercept(req: {
    method: string;
    path: string;
    query: URLSearchParams;
    /** The browser's role (absent: the gateway's own request, a read). */
    role?: Role;
    /** The request body when the gateway read it to classify it (a G-code body). */
    body?: string;
  }): HeldIntercept | null;
  /**
   * The credentials from the machines file the session is opened with (a typed login is then not
   * used). Default: the configured `password`. TouchCut: none (its `apiKey` is no login).
   */
  configured?(secrets: GatewaySecrets): HeldCredentials | undefined;
  /** Opens a session (`credentials`: the configured ones, else what a user typed, else none). */
  open(upstream: UpstreamRequest, credentials: HeldCredentials | undefined): Promise<HeldOpen>;
  /** Ends a session (unused, the gateway closing): best effort. */
  close?(upstream: UpstreamRequest, key: string): Promise<void>;
  /** Drops any key the browser sent from a forwarded HTTP request, then adds `key` (null: none). */
  apply(req: { headers: Record<string, string>; query: URLSearchParams }, key: string | null): void;
  /** The same for a WebSocket upgrade (the upstream URL's query and the upgrade's headers). */
  applyWs(req: { headers: Record<string, string>; query: URLSearchParams }, key: string | null): void;
  /**
   * The controller's status says the key is unknown or expired (DSF: 403; TouchCut: 401). `req`:
   * the request it answered, when there was one (a keep-alive has none).
   */
  isExpired(status: number, req?: { method: string; path: string }): boolean;
  /**
   * What happens when the key expired. 'reopen' (default): a new session is opened with the
   * configured or typed password (kept in memory for this) and a read is sent once more (DSF).
   * 'forget': the key is dropped and the controller's answer goes to the browser as it is, which
   * then asks for a login again; typed credentials are never kept (a user login that expired is
   * not renewed behind anyone's back: TouchCut).
   */
  expiry?: 'reopen' | 'forget';
  /**
   * The controller's answer to an `exchange` request (`session`: the session's current answer):
   * the key to hold from now on (null: unchanged) and the answer for the browser, which never holds
   * a key. A new key's `answer` also becomes the session's answer (what the next "open" gets).
   */
  exchanged?(
    answer: UpstreamAnswer,
    session: UpstreamAnswer | null,
  ): { key: string | null; answer: UpstreamAnswer };
  /**
   * `GET <path>` with the key every `everyMs` while a browser used the machine within
   * `whileUsedWithinMs` and no upstream socket holds the session open; unused longer, the session
   * is ended and the next request opens a new one.
   */
  keepAlive?: { path: string; everyMs: number; whileUsedWithinMs: number };
}

/** Everything a session gets from the console. */
export interface SessionContext {
  machine: MachineInfo;
  snapshot: StoreApi<MachineSnapshot>;
  log: MachineLog;
  commands: CommandRunner;
  /** On-demand reads of this machine (files, settings, stats): src/fleet/kernel/query.ts. */
  queries: MachineQueries;
  visibility: Visibility;
  /**
   * Whether a page shows this machine's details now (its machine page). Reads that only feed
   * details (positions at 4 Hz) may run at the tile's pace otherwise (issue 16: a fleet page of
   * 100 machines). True where nothing says otherwise (tests, the fault matrix).
   */
  detail: () => boolean;
  now: () => number;
}

export interface MachineSession {
  readonly machine: MachineInfo;
  readonly ctx: SessionContext;
  start(): void;
  /** Stop timers and sockets; say goodbye to the controller where the protocol wants it. */
  stop(): void;
  /** The declared commands, by id. */
  readonly commands: Readonly<Record<string, CommandDecl<never>>>;
  /** Acknowledge an alarm (clears the blocking banner; the controller may have its own ack). */
  acknowledgeAlarm?(alarmId: string): void;
  /** Log in when the machine says "needs login" (TouchCut user, Duet password). */
  login?(credentials: Record<string, string>): Promise<void>;
}

export interface TabProps<S extends MachineSession> {
  session: S;
}

export interface TabDecl<S extends MachineSession> {
  id: string;
  label: string;
  Component: ComponentType<TabProps<S>>;
  /** Least role that sees this tab at all (default viewer). */
  role?: Role;
}

/**
 * A family's page code (`<kind>/module.tsx`). Its name and kind only of the declaration: the
 * access rules and the gateway's hints are the console server's (they stay out of the page's
 * bundle, issue 16).
 */
export interface ControllerModule<S extends MachineSession = MachineSession> extends Pick<
  FamilyDeclaration,
  'kind' | 'label'
> {
  createSession(ctx: SessionContext): S;
  /** Tabs of the machine page; the first is the overview. */
  tabs: TabDecl<S>[];
  /** Optional extra on the fleet tile (a screenshot thumbnail). */
  TileExtra?: ComponentType<TabProps<S>>;
  /** Optional login form when the link says needs-login. */
  LoginForm?: ComponentType<TabProps<S>>;
}

/** Erases the session type so modules of all families fit one registry. */
export function defineController<S extends MachineSession>(m: ControllerModule<S>): ControllerModule {
  return m as unknown as ControllerModule;
}

/**
 * Link bookkeeping shared by sessions: writes link state, problem and retry time into the
 * snapshot, counts failures and computes the backoff.
 */
export class LinkTracker {
  failures = 0;

  constructor(private readonly ctx: SessionContext) {}

  get state(): LinkState {
    return this.ctx.snapshot.getState().link;
  }

  /** Good data arrived. */
  ok(patch: Partial<MachineSnapshot> = {}): void {
    const wasDown = this.state !== 'online';
    this.failures = 0;
    this.ctx.snapshot.setState({
      ...patch,
      link: 'online',
      problem: null,
      retryAt: null,
      updatedAt: this.ctx.now(),
    });
    if (wasDown) this.ctx.log.info('link', 'connected');
  }

  /** Merge vendor data into the snapshot without touching the link state. */
  patch(patch: Partial<MachineSnapshot>): void {
    this.ctx.snapshot.setState(patch);
  }

  /**
   * A request failed. Returns the delay before the next attempt. Network errors and timeouts
   * make the machine `reconnecting`, then `offline` after `offlineAfter` failures; a protocol
   * error shows the path that failed; 401/403 mean `needs-login` when `authFailure` says so.
   */
  fail(e: unknown, opts: { offlineAfter?: number; needsLogin?: boolean } = {}): number {
    this.failures++;
    const delay = backoffDelay(this.failures - 1);
    const err =
      e instanceof LinkError ? e : new LinkError('network', e instanceof Error ? e.message : String(e));
    const offlineAfter = opts.offlineAfter ?? 3;
    let link: LinkState;
    if (opts.needsLogin) link = 'needs-login';
    else if (err.kind === 'protocol') link = 'protocol-error';
    else if (this.failures >= offlineAfter) link = 'offline';
    else link = 'reconnecting';
    const prev = this.ctx.snapshot.getState();
    const offline = link === 'offline' || link === 'reconnecting';
    this.ctx.snapshot.setState({
      link,
      problem: err.toProblem(),
      retryAt: link === 'needs-login' ? null : this.ctx.now() + delay,
      ...(link === 'offline' ? { activity: 'offline', activityLabel: 'Offline' } : {}),
      ...(offline && prev.activity === 'unknown' ? { activityLabel: 'Connecting…' } : {}),
    });
    if (prev.link !== link || prev.problem?.message !== err.message) {
      this.ctx.log.add(
        link === 'protocol-error' ? 'error' : 'warning',
        'link',
        `${linkWords(link)}: ${err.message}`,
      );
    }
    return delay;
  }
}

export function linkWords(link: LinkState): string {
  switch (link) {
    case 'connecting':
      return 'Connecting';
    case 'online':
      return 'Online';
    case 'reconnecting':
      return 'Reconnecting';
    case 'needs-login':
      return 'Needs login';
    case 'protocol-error':
      return 'Protocol error';
    case 'offline':
      return 'Offline';
  }
}
