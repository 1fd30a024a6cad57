import type http from 'node:http';
import type { IncomingMessage, ServerResponse } from 'node:http';
import type { WebSocket } from 'ws';
import type { AccessDecision, AccessRequest } from '../src/fleet/access';
import type { HeldSessionHooks, SharingHints } from '../src/fleet/contract';
import type { FaultySimulator } from '../src/fleet/sim';
import type { Role } from '../src/fleet/types';
import type { AlarmCentre } from './alarms';
import type { AuditEntry, AuditLog } from './audit';
import type { ConsoleSession, FailureLimiter, IdleTimeouts, SessionStore } from './auth';
import type { HeldSessionHandle } from './held-types';
import type { History } from './history';
import type { Logger, Reachability } from './log';
import type { MachineEntry, MachinesConfig } from './machines';
import type { GatewayOptions } from './options';
import type { RefusalAggregator } from './refusals';
import type { SettingsStore } from './settings';
import type { StreamHubs } from './stream-hubs';
import type { PinStore } from './tls-pin';
import type { PinnedPools } from './tls-pool';
import type { UpstreamHttp, UpstreamStats } from './upstream-http';
import type { UserDirectory } from './users';
import type { Webhook } from './webhook';

/**
 * The gateway's services, each a narrow interface: a route module or a part of the gateway
 * names the ones it uses (`Pick` of them where it uses fewer members), so its signature says
 * what it touches. `GatewayContext` (context.ts) is their composition; alarms, history and
 * settings are stores the gateway makes beside it (gateway.ts, api.ts `ApiStores`).
 */

export interface Principal {
  name: string;
  role: Role;
  machines: string[] | null;
  /** The operator whose tablet a supervisor unlocked with a PIN. */
  onBehalfOf?: string;
}

export interface Who {
  mode: 'open' | 'secured';
  principal: Principal | null;
  session: ConsoleSession | null;
  expired: boolean;
}

export type Verdict =
  { ok: true; principal: Principal } | { ok: false; status: number; body: Record<string, unknown> };

export interface CommandAudit {
  /** The outcome (once; later calls do nothing). */
  done(r: { status?: number; error?: string }): void;
}

export interface MachineHints {
  session?: HeldSessionHooks;
  sharing?: SharingHints;
}

export interface LiveSocket {
  machine: string;
  /** The console session's token (null in open mode). */
  token: string | null;
  /** The least role the socket needs (its access decision). */
  needs: Role;
  close(code: number, reason: string): void;
}

/** How the gateway was configured, its clock, its log and whether it is closing. */
export interface ConfigService {
  readonly opts: GatewayOptions;
  readonly env: NodeJS.ProcessEnv;
  readonly cwd: string;
  readonly now: () => number;
  readonly config: MachinesConfig;
  readonly dataDir: string;
  readonly log: Logger;
  readonly timeoutMs: number;
  readonly state: { closed: boolean };
  /** The built-in demo fleet (no machines file, every machine simulated): demo jobs run. */
  readonly builtInDemo: boolean;
  hostAllowed(req: IncomingMessage): boolean;
}

/** Users and sessions: who is asking, logins, idle timeouts, PIN elevation, bridged sockets. */
export interface UsersService {
  readonly usersFile: string;
  readonly users: UserDirectory;
  readonly idle: IdleTimeouts;
  readonly elevationMs: number;
  readonly sessions: SessionStore;
  readonly limiter: FailureLimiter;
  /**
   * Bridged browser sockets and who opened them: re-checked on logout, expiry, removal and role
   * change (`revalidateSockets`), and closed when their user may no longer hold them.
   */
  readonly liveSockets: Map<WebSocket, LiveSocket>;
  /** Closes every bridged socket whose session, user, role or machine access is gone. */
  revalidateSockets(): void;
  who(req: IncomingMessage, touch: boolean): Who;
  sessionBody(w: Who): unknown;
  cookie(req: IncomingMessage, token: string, maxAge?: number): string;
  mayUseMachine(p: Principal, id: string): boolean;
  needLogin(res: ServerResponse, w: Who): void;
}

/** The audit log and its writers. */
export interface AuditService {
  readonly audit: AuditLog;
  /** Writes an audit entry; refusals pass `refusals` first (limited per user or address). */
  record(e: Omit<AuditEntry, 'time'>): void;
  /**
   * A command's audit entry, committed before the command is forwarded (audit.ts `begin`); its
   * `done` writes the outcome and tells the `onRecord` listeners. Null: the entry could not be
   * written (logged): the command must not be forwarded (answer 503).
   */
  beginCommand(e: Omit<AuditEntry, 'time' | 'result' | 'type'>): CommandAudit | null;
  /** Calls `listener` with every record written after it (the job history's commands); returns the removal. */
  onRecord(listener: (e: Omit<AuditEntry, 'time'>) => void): () => void;
  /** Limits refusals of unauthenticated clients per address (`dispose()` writes what is pending). */
  readonly refusals: RefusalAggregator;
}

/** The machines: lookup, access decisions, simulators (and serial boards), the families' hints. */
export interface MachinesService {
  readonly byId: Map<string, MachineEntry>;
  readonly sims: Map<string, FaultySimulator>;
  classify(m: MachineEntry, req: AccessRequest): AccessDecision;
  authorize(w: Who, m: MachineEntry, d: AccessDecision): Verdict;
  simulatorFor(m: MachineEntry): FaultySimulator | null;
  /**
   * The family's held-session hooks and sharing hints for this machine: the family's own, or
   * those of `gateway.forMachine` (made once per machine and kept: Duet learns DSF or standalone).
   */
  hintsOf(m: MachineEntry): MachineHints;
  /**
   * Throws a simulated machine's simulator away (its sockets closed, the session the gateway held
   * with it ended): the next request starts a fresh world without faults.
   */
  resetSimulator(m: MachineEntry): void;
  /** Runs the simulator's "demo" control (a job in progress), when it has one. */
  startDemoJob(m: MachineEntry): void;
}

/** The links to the controllers: HTTP and socket upstreams, pinned TLS, held sessions. */
export interface LinksService {
  /** Which controllers answer: logs a line when a machine goes offline or comes back. */
  readonly reachability: Reachability;
  readonly openSockets: Set<WebSocket>;
  readonly pending: Set<http.ClientRequest>;
  readonly httpAgent: http.Agent;
  /** Each machine's HTTP upstream, once: shared reads, read limits, keep-alive (upstream-http.ts). */
  readonly upstream: UpstreamHttp;
  /** Counters of a machine's upstream (benchmark, tests); null for an unknown machine. */
  upstreamStats(id: string): UpstreamStats | null;
  /** Shared controller sockets, one per machine and stream (streams.ts). */
  readonly streams: StreamHubs;
  /** Pinned TLS certificates of the controllers (tls-pin.ts). */
  readonly pins: PinStore;
  /** Kept-alive pinned TLS connections for reads, per machine (tls-pool.ts). */
  readonly tlsPools: PinnedPools;
  /** Controller sessions the gateway holds, by machine id (held-session.ts). */
  readonly heldSessions: Map<string, HeldSessionHandle>;
}

/** The machines' secrets: what is redacted from answers, frames, errors and the audit log. */
export interface SecretsService {
  readonly secretsOf: Map<string, string[]>;
  readonly allSecrets: string[];
  /** Every byte form of a machine's secrets, searched for in its answers and frames (redact.ts). */
  patternsFor(m: MachineEntry): readonly Buffer[];
  /**
   * A secret learned at run time (a held session key, a password typed into a login form): from
   * now on redacted like the configured ones (answers, frames, errors, audit); `false` forgets it.
   */
  learnSecret(machineId: string, value: string, known?: boolean): void;
  scrub(text: string): string;
}

/** The alarm centre (alarms.ts). */
export interface AlarmsService {
  alarms: AlarmCentre;
}

/** The production history (history/); absent: its routes answer 404. */
export interface HistoryService {
  history?: History;
}

/** The server settings (settings.ts) and the webhook that uses them. */
export interface SettingsService {
  settings: SettingsStore;
  webhook: Webhook;
}
