import { PinStore } from './tls-pin';
import { StreamHubs } from './streams';
import { secretPatterns } from './redact';
import http, { type IncomingMessage, type ServerResponse } from 'node:http';
import { isIP } from 'node:net';
import { WebSocket } from 'ws';
import { defaultDecision, type AccessDecision, type AccessRequest } from '../src/fleet/access';
import type { HeldSessionHooks, SharingHints } from '../src/fleet/contract';
import { FaultySimulator } from '../src/fleet/sim';
import { roleAtLeast, type MachineKind, type Role } from '../src/fleet/types';
import { AuditLog, type AuditEntry, type AuditLogOptions } from './audit';
import { loggerFromEnv, Reachability, type Logger } from './log';
import {
  DEFAULT_ELEVATION_S,
  DEFAULT_IDLE,
  DEFAULT_RATE_LIMIT,
  FailureLimiter,
  SESSION_COOKIE,
  SessionStore,
  SqliteSessionFile,
  type ConsoleSession,
  type IdleTimeouts,
  type RateLimitOptions,
} from './auth';
import { clientAddress, parseCookies, sendJson } from './http-util';
import { loadMachines, redact, secretForms, type MachineEntry, type MachinesConfig } from './machines';
import { UserDirectory, dataDirPath, usersFilePath } from './users';
import type { HeldSession } from './held-session';
import { UpstreamHttp, type UpstreamLimits, type UpstreamStats } from './upstream-http';
import type { DiscoveryOptions, NodeFamily, PortOpener } from '../src/fleet/server-part';

export type Families = Partial<Record<MachineKind, NodeFamily>>;

export interface GatewayOptions {
  /** How serial machines' ports are opened (tests: the serialport mock binding). Default: the real ports. */
  serialOpener?: PortOpener;
  /**
   * A serial board that sends nothing this long while it runs is "stuck in run", ms (default
   * 10 s; SHOPDECK_SERIAL_WATCHDOG_S).
   */
  serialWatchdogMs?: number;
  /** Open mode served beyond this computer (SHOPDECK_OPEN=1): the page's banner says so. */
  openOnNetwork?: boolean;
  machinesFile?: string;
  dataDir?: string;
  usersFile?: string;
  env?: NodeJS.ProcessEnv;
  cwd?: string;
  /** Already loaded machines (the plugin validates at config time). */
  machines?: MachinesConfig;
  /** The family registry (src/controllers/families.ts). */
  families: Families;
  /** Clock for sessions, rate limits, elevation and the windows of shared reads (tests). */
  now?: () => number;
  /** Per-request timeout towards a controller, ms (default 15 s; SHOPDECK_PROXY_TIMEOUT_MS). */
  timeoutMs?: number;
  /** Idle timeouts per role, seconds (SHOPDECK_IDLE_<ROLE>_S). */
  idleTimeoutS?: Partial<IdleTimeouts>;
  /** How long a PIN elevation lasts, seconds (SHOPDECK_ELEVATION_S). */
  elevationS?: number;
  rateLimit?: Partial<RateLimitOptions>;
  discovery?: Partial<DiscoveryOptions>;
  /**
   * Host names the console may be reached by (DNS rebinding protection, as Vite's
   * `server.allowedHosts`): `true` for any; IP addresses and localhost are always allowed.
   */
  allowedHosts?: true | readonly string[];
  /** Where the gateway's log lines go (default: `SHOPDECK_LOG=json` or text, stdout/stderr). */
  log?: Logger;
  /**
   * The audit log (tests): retention defaults to `SHOPDECK_AUDIT_DAYS` (400),
   * `SHOPDECK_AUDIT_REFUSAL_DAYS` (30) and `SHOPDECK_AUDIT_REFUSAL_MAX` (100,000).
   */
  audit?: Omit<AuditLogOptions, 'role'>;
  /** Bounds of the shared upstream (upstream-http.ts; tests): queue, kept answers, sizes. */
  upstream?: Partial<UpstreamLimits>;
  /**
   * The gateway's own slow watch of every machine (watch.ts), with or without a viewer. On
   * unless false (gateway tests that count every request to a controller turn it off).
   */
  watch?: boolean;
}

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

export function envNumber(env: NodeJS.ProcessEnv, key: string): number | undefined {
  const v = env[key];
  if (!v) return undefined;
  const n = Number(v);
  return Number.isFinite(n) && n > 0 ? n : undefined;
}

/** What every part of the gateway shares: configuration, identity, audit, upstream bookkeeping. */
export interface GatewayContext {
  readonly opts: GatewayOptions;
  readonly env: NodeJS.ProcessEnv;
  readonly cwd: string;
  readonly now: () => number;
  readonly config: MachinesConfig;
  readonly dataDir: string;
  readonly usersFile: string;
  readonly users: UserDirectory;
  readonly audit: AuditLog;
  readonly log: Logger;
  /** Which controllers answer: logs a line when a machine goes offline or comes back. */
  readonly reachability: Reachability;
  readonly timeoutMs: number;
  readonly idle: IdleTimeouts;
  readonly elevationMs: number;
  readonly sessions: SessionStore;
  readonly limiter: FailureLimiter;
  readonly byId: Map<string, MachineEntry>;
  readonly secretsOf: Map<string, string[]>;
  readonly allSecrets: string[];
  readonly sims: Map<string, FaultySimulator>;
  readonly openSockets: Set<WebSocket>;
  readonly pending: Set<http.ClientRequest>;
  readonly httpAgent: http.Agent;
  /** Each machine's HTTP upstream, once: shared reads, read limits, keep-alive (upstream-http.ts). */
  readonly upstream: UpstreamHttp;
  /** Counters of a machine's upstream (benchmark, tests); null for an unknown machine. */
  upstreamStats(id: string): UpstreamStats | null;
  readonly state: { closed: boolean };
  /**
   * Bridged browser sockets and who opened them: re-checked on logout, expiry, removal and role
   * change (`revalidateSockets`), and closed when their user may no longer hold them.
   */
  readonly liveSockets: Map<WebSocket, LiveSocket>;
  /** Shared controller sockets, one per machine and stream (streams.ts). */
  readonly streams: StreamHubs;
  /** Closes every bridged socket whose session, user, role or machine access is gone. */
  revalidateSockets(): void;
  /** Pinned TLS certificates of the controllers (tls-pin.ts). */
  readonly pins: PinStore;
  /** Every byte form of a machine's secrets, searched for in its answers and frames (redact.ts). */
  patternsFor(m: MachineEntry): readonly Buffer[];
  /** Controller sessions the gateway holds, by machine id (held-session.ts). */
  readonly heldSessions: Map<string, HeldSession>;
  /**
   * A secret learned at run time (a held session key, a password typed into a login form): from
   * now on redacted like the configured ones (answers, frames, errors, audit); `false` forgets it.
   */
  learnSecret(machineId: string, value: string, known?: boolean): void;
  hostAllowed(req: IncomingMessage): boolean;
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
  scrub(text: string): string;
  who(req: IncomingMessage, touch: boolean): Who;
  sessionBody(w: Who): unknown;
  cookie(req: IncomingMessage, token: string, maxAge?: number): string;
  mayUseMachine(p: Principal, id: string): boolean;
  needLogin(res: ServerResponse, w: Who): void;
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
  /** The built-in demo fleet (no machines file, every machine simulated): demo jobs run. */
  readonly builtInDemo: boolean;
  /** Runs the simulator's "demo" control (a job in progress), when it has one. */
  startDemoJob(m: MachineEntry): void;
}

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

export type Verdict =
  { ok: true; principal: Principal } | { ok: false; status: number; body: Record<string, unknown> };

export function createContext(opts: GatewayOptions): GatewayContext {
  const env = opts.env ?? process.env;
  const cwd = opts.cwd ?? process.cwd();
  const now = opts.now ?? Date.now;
  const config = opts.machines ?? loadMachines({ machinesFile: opts.machinesFile, env, cwd });
  const dataDir = dataDirPath({ dataDir: opts.dataDir, env, cwd });
  const usersFile = usersFilePath({ usersFile: opts.usersFile, dataDir, env, cwd });
  const log = opts.log ?? loggerFromEnv(env);
  const reachability = new Reachability(log);
  const users = new UserDirectory(usersFile, log);
  const audit = new AuditLog(dataDir, {
    role: 'server',
    log,
    now,
    ...opts.audit,
    retention: {
      ...(envNumber(env, 'SHOPDECK_AUDIT_DAYS') ? { recordDays: envNumber(env, 'SHOPDECK_AUDIT_DAYS') } : {}),
      ...(envNumber(env, 'SHOPDECK_AUDIT_REFUSAL_DAYS')
        ? { refusalDays: envNumber(env, 'SHOPDECK_AUDIT_REFUSAL_DAYS') }
        : {}),
      ...(envNumber(env, 'SHOPDECK_AUDIT_REFUSAL_MAX')
        ? { refusalMax: envNumber(env, 'SHOPDECK_AUDIT_REFUSAL_MAX') }
        : {}),
      ...opts.audit?.retention,
    },
  });
  const timeoutMs = opts.timeoutMs ?? envNumber(env, 'SHOPDECK_PROXY_TIMEOUT_MS') ?? 15_000;
  const idle: IdleTimeouts = {
    viewer: opts.idleTimeoutS?.viewer ?? envNumber(env, 'SHOPDECK_IDLE_VIEWER_S') ?? DEFAULT_IDLE.viewer,
    operator:
      opts.idleTimeoutS?.operator ?? envNumber(env, 'SHOPDECK_IDLE_OPERATOR_S') ?? DEFAULT_IDLE.operator,
    supervisor:
      opts.idleTimeoutS?.supervisor ??
      envNumber(env, 'SHOPDECK_IDLE_SUPERVISOR_S') ??
      DEFAULT_IDLE.supervisor,
  };
  const elevationMs =
    (opts.elevationS ?? envNumber(env, 'SHOPDECK_ELEVATION_S') ?? DEFAULT_ELEVATION_S) * 1000;
  // Kept in the history database across restarts (auth.ts): only a hash of each token.
  const sessions = new SessionStore(idle, now, new SqliteSessionFile(audit.file), (e) =>
    log.error('the session file cannot be written: sessions are kept in memory only', { error: String(e) }),
  );
  const limiter = new FailureLimiter({ ...DEFAULT_RATE_LIMIT, ...opts.rateLimit }, now);
  const byId = new Map(config.machines.map((m) => [m.id, m]));
  const secretsOf = new Map(config.machines.map((m) => [m.id, secretForms(m.secrets)]));
  const allSecrets = [...new Set(config.machines.flatMap((m) => secretForms(m.secrets)))];
  const sims = new Map<string, FaultySimulator>();
  const hints = new Map<string, MachineHints>();
  function hintsOf(m: MachineEntry): MachineHints {
    let h = hints.get(m.id);
    if (!h) {
      const g = opts.families[m.kind]?.gateway;
      h = g?.forMachine
        ? g.forMachine({ id: m.id, ...(m.api ? { api: m.api } : {}) })
        : { session: g?.session, sharing: g?.sharing };
      hints.set(m.id, h);
    }
    return h;
  }
  const openSockets = new Set<WebSocket>();
  const pending = new Set<http.ClientRequest>();
  const httpAgent = new http.Agent({ keepAlive: false });
  // No https agent: an https:/wss: controller is reached only over a pinned TLS socket
  // (tls-pin.ts connectPinned), whose certificate is checked before a byte is sent.
  const upstream = new UpstreamHttp({
    sharingOf: (m) => hintsOf(m).sharing,
    timeoutMs,
    now,
    httpAgent,
    scrub: (text) => redact(text, allSecrets),
    limits: opts.upstream,
  });
  const upstreamStats = (id: string): UpstreamStats | null => (byId.has(id) ? upstream.stats(id) : null);
  const state = { closed: false };
  const liveSockets = new Map<WebSocket, LiveSocket>();
  const streams = new StreamHubs();
  const pins = new PinStore(dataDir);
  const patternCache = new Map<string, readonly Buffer[]>();
  const patternsFor = (m: MachineEntry): readonly Buffer[] => {
    let p = patternCache.get(m.id);
    if (!p) {
      p = secretPatterns([m.secrets, ...[...(learned.get(m.id) ?? [])].map((v) => ({ password: v }))]);
      patternCache.set(m.id, p);
    }
    return p;
  };
  // Held controller sessions (held-session.ts) and the secrets they learn at run time.
  const heldSessions = new Map<string, HeldSession>();
  const learned = new Map<string, Set<string>>();
  const learnSecret = (machineId: string, value: string, known = true): void => {
    const set = learned.get(machineId) ?? new Set<string>();
    learned.set(machineId, set);
    if (known === set.has(value)) return;
    if (known) set.add(value);
    else set.delete(value);
    const formsOf = (id: string): string[] => {
      const configured = byId.get(id)?.secrets ?? {};
      const extra = [...(learned.get(id) ?? [])].flatMap((v) => secretForms({ password: v }));
      return [...new Set([...secretForms(configured), ...extra])].sort((a, b) => b.length - a.length);
    };
    secretsOf.set(machineId, formsOf(machineId));
    const all = [...new Set([...config.machines.map((m) => m.id), ...learned.keys()].flatMap(formsOf))];
    allSecrets.splice(0, allSecrets.length, ...all.sort((a, b) => b.length - a.length));
    patternCache.delete(machineId);
  };

  const allowedHosts = opts.allowedHosts ?? true;
  function hostAllowed(req: IncomingMessage): boolean {
    if (allowedHosts === true) return true;
    let hostname: string;
    try {
      hostname = new URL(`http://${req.headers.host ?? ''}`).hostname.replace(/^\[|\]$/g, '');
    } catch {
      return false;
    }
    if (!hostname) return false;
    if (hostname === 'localhost' || hostname.endsWith('.localhost') || isIP(hostname)) return true;
    return allowedHosts.some((a) =>
      a.startsWith('.') ? hostname === a.slice(1) || hostname.endsWith(a) : hostname === a.toLowerCase(),
    );
  }

  const nowIso = (): string => new Date(now()).toISOString();
  const append = (e: Omit<AuditEntry, 'time'> & { time?: string }): void => {
    try {
      audit.append({ ...e, time: e.time ?? nowIso() });
    } catch (err) {
      log.error('could not write the audit log', { error: String(err) });
    }
  };
  // Refusals (and attempts the login/PIN limiter refused) are limited per user, or per address
  // for clients without a session.
  const refusals = new RefusalAggregator(REFUSAL_LIMIT, now, append);
  const recordListeners = new Set<(e: Omit<AuditEntry, 'time'>) => void>();
  const record = (e: Omit<AuditEntry, 'time'>): void => {
    if (refusals.admit(e)) append(e);
    tell(e);
  };
  const beginCommand = (e: Omit<AuditEntry, 'time' | 'result' | 'type'>): CommandAudit | null => {
    let begun: { entry: AuditEntry; id: number };
    try {
      begun = audit.begin({ ...e, type: 'command', time: nowIso() });
    } catch (err) {
      log.error('a command was refused: its audit entry cannot be written', {
        machine: e.machine,
        user: e.user,
        label: e.label,
        error: String(err),
      });
      return null;
    }
    let finished = false;
    return {
      done(r) {
        if (finished) return;
        finished = true;
        const ok = r.status !== undefined && r.status < 400 && r.error === undefined;
        const entry: AuditEntry = { ...begun.entry, result: ok ? 'ok' : 'error', ...r };
        try {
          audit.finish(begun.id, entry);
        } catch (err) {
          log.error('could not write the outcome of a command to the audit log', {
            machine: e.machine,
            error: String(err),
          });
        }
        const { time: _time, ...rest } = entry;
        tell(rest);
      },
    };
  };
  const tell = (e: Omit<AuditEntry, 'time'>): void => {
    for (const l of recordListeners) {
      try {
        l(e);
      } catch (err) {
        log.error('a listener of the audit records failed', { error: String(err) });
      }
    }
  };
  const onRecord = (listener: (e: Omit<AuditEntry, 'time'>) => void): (() => void) => {
    recordListeners.add(listener);
    return () => recordListeners.delete(listener);
  };
  const scrub = (text: string): string => redact(text, allSecrets);
  // ---------------------------------------------------------------- who is asking

  // Sessions kept from before a restart are checked against the users file at the first request.
  let seenUsers = Number.NaN;
  /**
   * Sessions follow the users file as soon as it changes (any request notices): a session takes
   * its user's new role (and with it the idle timeout), an unlock ends when the tablet's user is
   * no longer an operator, a removed user's sessions end; then bridged sockets are re-checked.
   */
  function followUsersFile(): void {
    const generation = users.generation;
    if (generation === seenUsers) return;
    seenUsers = generation;
    const seen = new Set<string>();
    for (const s of sessions.list()) {
      const u = users.find(s.user);
      if (!u) {
        const n = sessions.dropUser(s.user);
        record({
          type: 'user-removed',
          result: 'ok',
          user: s.user,
          source: 'gateway',
          detail: `no longer in the users file: ${n} session${n === 1 ? '' : 's'} ended`,
        });
        continue;
      }
      if (u.role !== s.role) {
        if (!seen.has(u.name))
          record({
            type: 'role-change',
            result: 'ok',
            user: u.name,
            role: u.role,
            source: 'gateway',
            detail: `${s.role} → ${u.role} (seen by the gateway on a live session: idle timeout now ${sessions.idleSeconds(u.role)} s)`,
          });
        seen.add(u.name);
        s.role = u.role;
        sessions.save(s);
      }
      if (s.elevation && u.role !== 'operator') {
        record({
          type: 'elevate-end',
          result: 'ok',
          user: s.elevation.supervisor,
          onBehalfOf: u.name,
          source: 'gateway',
          detail: `${u.name} is no longer an operator`,
        });
        s.elevation = null;
      }
    }
    revalidateSockets();
  }

  function who(req: IncomingMessage, touch: boolean): Who {
    if (users.mode === 'open') {
      return {
        mode: 'open',
        principal: { name: 'anonymous', role: 'supervisor', machines: null },
        session: null,
        expired: false,
      };
    }
    followUsersFile();
    const token = parseCookies(req.headers.cookie)[SESSION_COOKIE];
    const s = sessions.get(token, touch);
    if (s && 'expired' in s) {
      record({
        type: 'session-expired',
        result: 'ok',
        user: s.expired.user,
        source: 'gateway',
        address: clientAddress(req),
        detail: `no activity for ${sessions.idleSeconds(s.expired.role)} s`,
      });
      return { mode: 'secured', principal: null, session: null, expired: true };
    }
    if (!s) return { mode: 'secured', principal: null, session: null, expired: false };
    const u = users.find(s.user);
    if (!u) {
      sessions.dropUser(s.user);
      return { mode: 'secured', principal: null, session: null, expired: false };
    }
    if (s.elevation) {
      const sup = users.find(s.elevation.supervisor);
      if (sup && sup.role === 'supervisor' && u.role === 'operator') {
        return {
          mode: 'secured',
          principal: { name: sup.name, role: 'supervisor', machines: sup.machines, onBehalfOf: u.name },
          session: s,
          expired: false,
        };
      }
      s.elevation = null;
    }
    return {
      mode: 'secured',
      principal: { name: u.name, role: u.role, machines: u.machines },
      session: s,
      expired: false,
    };
  }

  /**
   * `GET /api/session`. `user` is who the gateway acts as right now: during a PIN elevation
   * the supervisor, with the operator whose tablet it is in `elevation.operator`.
   */
  function sessionBody(w: Who): unknown {
    const u = w.session ? users.find(w.session.user) : null;
    const p = w.mode === 'secured' ? w.principal : null;
    return {
      mode: w.mode,
      ...(w.mode === 'open' ? { openOnNetwork: opts.openOnNetwork === true } : {}),
      user: p ? { name: p.name, role: p.role, machines: p.machines } : null,
      idleTimeoutS: u ? sessions.idleSeconds(w.session?.role ?? u.role) : null,
      elevation:
        w.session?.elevation && p?.onBehalfOf && u
          ? {
              supervisor: w.session.elevation.supervisor,
              until: new Date(w.session.elevation.until).toISOString(),
              operator: { name: u.name, role: u.role, machines: u.machines },
            }
          : null,
      expired: w.expired,
    };
  }

  function cookie(req: IncomingMessage, token: string, maxAge?: number): string {
    const secure = (req.socket as { encrypted?: boolean }).encrypted ? '; Secure' : '';
    const age = maxAge !== undefined ? `; Max-Age=${maxAge}` : '';
    return `${SESSION_COOKIE}=${token}; Path=/; HttpOnly; SameSite=Strict${secure}${age}`;
  }

  function mayUseMachine(p: Principal, id: string): boolean {
    return p.machines === null || p.machines.includes(id);
  }

  function needLogin(res: ServerResponse, w: Who): void {
    sendJson(res, 401, {
      error: w.expired ? 'your session expired: log in again' : 'log in first',
      needs: 'viewer',
      login: true,
    });
  }

  // ---------------------------------------------------------------- access control

  function classify(m: MachineEntry, req: AccessRequest): AccessDecision {
    const fam = opts.families[m.kind];
    if (!fam) return defaultDecision(req);
    try {
      return fam.access(req);
    } catch (e) {
      return {
        role: 'supervisor',
        command: true,
        label: `${req.method} ${req.path} (the access rule failed: supervisor only; ${e instanceof Error ? e.message : String(e)})`,
      };
    }
  }

  function authorize(w: Who, m: MachineEntry, d: AccessDecision): Verdict {
    if (!w.principal) {
      return {
        ok: false,
        status: 401,
        body: {
          error: w.expired ? 'your session expired: log in again' : 'log in first',
          needs: d.role,
          login: true,
        },
      };
    }
    const p = w.principal;
    if (!mayUseMachine(p, m.id)) {
      return {
        ok: false,
        status: 403,
        body: { error: `${p.name} may not use the machine ${m.id}`, needs: d.role },
      };
    }
    if (!roleAtLeast(p.role, d.role)) {
      return {
        ok: false,
        status: 403,
        body: { error: `${d.label}: needs the ${d.role} role (${p.name} is ${p.role})`, needs: d.role },
      };
    }
    return { ok: true, principal: p };
  }

  const watchdogS = envNumber(env, 'SHOPDECK_SERIAL_WATCHDOG_S');
  // At least 1 s: a shorter watchdog would call every pause between two reports a stuck board.
  const serialWatchdogMs = opts.serialWatchdogMs ?? Math.max(1, watchdogS ?? 10) * 1000;

  /**
   * A board on a serial port (issue 19): its family's server part (`serial`) answers the family's
   * API from it, in place of a simulator (never simulated: no faults can be injected, the dev
   * panel is off). Null when the family drives no serial board (the machines file refuses that).
   */
  function serialBridge(
    m: MachineEntry & { serial: { path: string; baudRate: number } },
  ): FaultySimulator | null {
    const part = opts.families[m.kind]?.server?.serial;
    if (!part) return null;
    const bridge = part.open({
      id: m.id,
      name: m.name,
      path: m.serial.path,
      baudRate: m.serial.baudRate,
      ...(opts.serialOpener ? { opener: opts.serialOpener } : {}),
      watchdogMs: serialWatchdogMs,
      event: (level, message) => log[level](`${m.id}: ${message}`, { machine: m.id }),
    });
    return new FaultySimulator(bridge);
  }

  function simulatorFor(m: MachineEntry): FaultySimulator | null {
    let sim = sims.get(m.id);
    if (sim) return sim;
    if (m.serial) {
      if (state.closed) return null;
      sim = serialBridge({ ...m, serial: m.serial }) ?? undefined;
      if (sim) sims.set(m.id, sim);
      return sim ?? null;
    }
    const fam = opts.families[m.kind];
    if (!fam) return null;
    sim = new FaultySimulator(
      fam.createSimulator({ id: m.id, name: m.name, ...(m.api ? { machineApi: m.api } : {}) }),
    );
    sims.set(m.id, sim);
    return sim;
  }

  function resetSimulator(m: MachineEntry): void {
    // A serial board's bridge owns its port and its job: never thrown away from the dev panel.
    if (m.serial) return;
    const held = heldSessions.get(m.id);
    if (held) {
      held.end();
      heldSessions.delete(m.id);
    }
    const sim = sims.get(m.id);
    if (!sim) return;
    sims.delete(m.id);
    sim.closeSockets();
    sim.dispose();
  }

  // Serial boards are opened at once: the gateway owns each port from the start, viewers or not.
  for (const m of config.machines) if (m.serial) simulatorFor(m);

  const builtInDemo = config.file === null && config.machines.every((m) => m.simulated);

  function startDemoJob(m: MachineEntry): void {
    if (!m.simulated) return;
    try {
      simulatorFor(m)
        ?.controls()
        .find((c) => c.id === 'demo')
        ?.run();
    } catch (e) {
      log.error(`${m.id}: the simulator's demo job did not start`, { machine: m.id, error: String(e) });
    }
  }

  function revalidateSockets(): void {
    if (users.mode === 'open') return;
    for (const [sock, live] of liveSockets) {
      const why = socketProblem(live);
      if (why) {
        liveSockets.delete(sock);
        live.close(4401, why);
      }
    }
  }

  /** Why a bridged socket may no longer stay open, or null. */
  function socketProblem(live: LiveSocket): string | null {
    const s = sessions.get(live.token ?? undefined, false);
    if (!s) return 'logged out';
    if ('expired' in s) return 'session expired';
    const u = users.find(s.user);
    if (!u) return 'user removed';
    const name = s.elevation ? s.elevation.supervisor : u.name;
    const p = s.elevation ? users.find(s.elevation.supervisor) : u;
    if (!p) return 'user removed';
    if (!roleAtLeast(s.elevation ? 'supervisor' : p.role, live.needs))
      return `${name} no longer has the ${live.needs} role`;
    if (!mayUseMachine({ name, role: p.role, machines: p.machines }, live.machine))
      return `${name} may no longer use ${live.machine}`;
    return null;
  }

  return {
    opts,
    env,
    cwd,
    now,
    config,
    dataDir,
    usersFile,
    users,
    audit,
    log,
    reachability,
    timeoutMs,
    idle,
    elevationMs,
    sessions,
    limiter,
    byId,
    secretsOf,
    allSecrets,
    sims,
    openSockets,
    pending,
    httpAgent,
    upstream,
    upstreamStats,
    hostAllowed,
    record,
    beginCommand,
    onRecord,
    scrub,
    who,
    sessionBody,
    cookie,
    mayUseMachine,
    needLogin,
    classify,
    authorize,
    simulatorFor,
    hintsOf,
    resetSimulator,
    builtInDemo,
    startDemoJob,
    state,
    liveSockets,
    streams,
    revalidateSockets,
    refusals,
    patternsFor,
    pins,
    heldSessions,
    learnSecret,
  };
}

// ---------------------------------------------------------------- refusals of unknown clients

export interface RefusalLimit {
  windowMs: number;
  /** Entries per user (or per address, without a session) written in a window; the rest are counted into one summary. */
  firstN: number;
}

export const REFUSAL_LIMIT: RefusalLimit = { windowMs: 60_000, firstN: 10 };

type AuditRecord = Omit<AuditEntry, 'time'>;

/**
 * What a client can make the gateway write as often as it likes: refusals (of anyone: a signed-in
 * viewer's forged commands as much as a client without a session) and attempts the login/PIN
 * limiter refused.
 */
function floodable(e: AuditRecord): boolean {
  if (e.type === 'refused') return true;
  return (e.type === 'login-failed' || e.type === 'elevate-failed') && e.result === 'refused';
}

interface RefusalWindow {
  start: number;
  written: number;
  more: number;
  user: string;
  address: string;
  machines: Set<string>;
}

/**
 * Keeps refusals from filling the audit log: per signed-in user (`user: "nobody"`, no session:
 * per address), the first `firstN` in a window are written, the rest counted and written as ONE
 * entry ("37 more refused requests by vic (from 10.0.0.9) in the last minute", timed at the
 * window's end) when the window ends: on the next record (`admit`) or from an unref'd timer,
 * whichever comes first. Everything else passes. (Refusals are also kept apart from commands in
 * the audit table, audit.ts: they never push a command out.)
 */
export class RefusalAggregator {
  private windows = new Map<string, RefusalWindow>();
  private timer: NodeJS.Timeout | null = null;

  constructor(
    private readonly limit: RefusalLimit,
    private readonly now: () => number,
    private readonly write: (e: AuditRecord & { time: string }) => void,
  ) {}

  /** True: write `e` now. False: it was counted into its user's (or address's) summary. */
  admit(e: AuditRecord): boolean {
    const t = this.now();
    this.flush(t);
    if (!floodable(e)) return true;
    const address = e.address ?? 'unknown';
    const user = e.user || 'nobody';
    const key = user === 'nobody' ? `address ${address}` : `user ${user}`;
    let w = this.windows.get(key);
    if (!w) {
      if (this.windows.size >= 10_000) this.flush(Number.POSITIVE_INFINITY);
      w = { start: t, written: 0, more: 0, user, address, machines: new Set() };
      this.windows.set(key, w);
    }
    if (w.written < this.limit.firstN) {
      w.written++;
      return true;
    }
    w.more++;
    w.address = address;
    if (e.machine && w.machines.size < 5) w.machines.add(e.machine);
    this.arm();
    return false;
  }

  /** Writes the summaries of the windows that ended by `t` (every window: `Infinity`). */
  flush(t: number = this.now()): void {
    for (const [key, w] of this.windows) {
      const end = w.start + this.limit.windowMs;
      if (end > t) continue;
      this.windows.delete(key);
      if (!w.more) continue;
      const span = this.limit.windowMs === 60_000 ? 'minute' : `${Math.round(this.limit.windowMs / 1000)} s`;
      const by = w.user === 'nobody' ? `from ${w.address}` : `by ${w.user} (from ${w.address})`;
      const on = w.user !== 'nobody' && w.machines.size ? ` (machines: ${[...w.machines].join(', ')})` : '';
      this.write({
        type: 'refused',
        result: 'refused',
        user: w.user,
        source: 'gateway',
        address: w.address,
        detail: `${w.more} more refused requests ${by} in the last ${span}${on}`,
        time: new Date(Math.min(end, this.now())).toISOString(),
      });
    }
  }

  /** Writes every pending summary and stops the timer (the gateway closes). */
  dispose(): void {
    if (this.timer) clearTimeout(this.timer);
    this.timer = null;
    this.flush(Number.POSITIVE_INFINITY);
  }

  private arm(): void {
    if (this.timer) return;
    this.timer = setTimeout(() => {
      this.timer = null;
      this.flush();
      if ([...this.windows.values()].some((w) => w.more > 0)) this.arm();
    }, this.limit.windowMs);
    this.timer.unref();
  }
}
