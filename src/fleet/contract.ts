import type { ComponentType } from 'react';
import type { StoreApi } from 'zustand/vanilla';
import type { AccessPolicy, BodyNeeded } from './access';
import type { CommandDecl, CommandRunner } from './commands';
import { LinkError } from './errors';
import { backoffDelay, type Visibility } from './link';
import type { MachineQueries } from './kernel/query';
import type { MachineLog } from './log';
import type { SimulatorFactory } from './sim';
import type { LinkState, MachineInfo, MachineKind, MachineSnapshot, Role } from './types';

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
  gateway?: GatewayHints;
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
) => Promise<UpstreamAnswer>;

/** Requests the gateway answers itself from a held session. */
export type HeldIntercept =
  /** The browser's "connect": answered with the session's `answer`; `password` if the user typed one. */
  | { kind: 'open'; password?: string }
  /** The browser's "disconnect": answered locally, the shared session stays. */
  | { kind: 'close' };

export type HeldOpen =
  /** `key` null: the controller wants none (no password protection). `answer` never holds the key. */
  | { ok: true; key: string | null; answer: UpstreamAnswer }
  /** Refused (wrong password): the controller's answer, for the browser as it is. */
  | { ok: false; answer: UpstreamAnswer };

/** A family's declaration that the gateway holds the controller's session (Node-safe, pure). */
export interface HeldSessionHooks {
  /** Requests the gateway answers itself instead of forwarding them, or null. */
  intercept(req: { method: string; path: string; query: URLSearchParams }): HeldIntercept | null;
  /** Opens a session (`password`: the configured one, else one a user typed, else none). */
  open(upstream: UpstreamRequest, password: string | undefined): Promise<HeldOpen>;
  /** Ends a session (unused, the gateway closing): best effort. */
  close?(upstream: UpstreamRequest, key: string): Promise<void>;
  /** Drops any key the browser sent from a forwarded HTTP request, then adds `key` (null: none). */
  apply(req: { headers: Record<string, string>; query: URLSearchParams }, key: string | null): void;
  /** The same for a WebSocket upgrade (the upstream URL's query and the upgrade's headers). */
  applyWs(req: { headers: Record<string, string>; query: URLSearchParams }, key: string | null): void;
  /** The controller's status says the key is unknown or expired (DSF: 403). */
  isExpired(status: number): boolean;
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

export interface ControllerModule<S extends MachineSession = MachineSession> extends FamilyDeclaration {
  createSession(ctx: SessionContext): S;
  /** Tabs of the machine page; the first is the overview. */
  tabs: TabDecl<S>[];
  /** Optional extra on the fleet tile (a screenshot thumbnail). */
  TileExtra?: ComponentType<TabProps<S>>;
  /** Optional login form when the link says needs-login. */
  LoginForm?: ComponentType<TabProps<S>>;
  /** Family-level pages outside any machine (xTool "Find lasers"), routed at `/<kind>/<path>`. */
  pages?: Array<{ path: string; label: string; Component: ComponentType }>;
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
