import bcrypt from 'bcryptjs';
import { randomBytes } from 'node:crypto';
import http, { type IncomingMessage, type ServerResponse } from 'node:http';
import https from 'node:https';
import { isIP } from 'node:net';
import type { Duplex } from 'node:stream';
import { WebSocket, WebSocketServer, type RawData } from 'ws';
import { z } from 'zod';
import { defaultDecision, type AccessDecision, type AccessRequest } from '../src/fleet/access';
import type { FamilyDescriptor } from '../src/fleet/contract';
import { FaultySimulator, SimDropped } from '../src/fleet/sim';
import { roleAtLeast, type MachineKind, type Role } from '../src/fleet/types';
import { AuditLog, auditQueryFrom, toCsv, type AuditEntry } from './audit';
import {
  DEFAULT_ELEVATION_S,
  DEFAULT_IDLE,
  DEFAULT_RATE_LIMIT,
  FailureLimiter,
  SESSION_COOKIE,
  SessionStore,
  type ConsoleSession,
  type IdleTimeouts,
  type RateLimitOptions,
} from './auth';
import { discoverXtool, type DiscoveryOptions } from './discovery';
import {
  BodyTooLarge,
  clientAddress,
  forwardRequestHeaders,
  forwardResponseHeaders,
  parseCookies,
  readBody,
  readJson,
  rejectUpgrade,
  sameOrigin,
  sendJson,
} from './http-util';
import {
  loadMachines,
  machineInfo,
  redact,
  secretForms,
  type MachineEntry,
  type MachinesConfig,
} from './machines';
import { splitTarget } from './paths';
import { bridgeSimSocket } from './sim-server';
import { UserDirectory, checkSecret, dataDirPath, usersFilePath, type UserRecord } from './users';

export type Families = Partial<Record<MachineKind, FamilyDescriptor>>;

export interface GatewayOptions {
  machinesFile?: string;
  dataDir?: string;
  usersFile?: string;
  env?: NodeJS.ProcessEnv;
  cwd?: string;
  /** Already loaded machines (the plugin validates at config time). */
  machines?: MachinesConfig;
  /** The family registry (src/controllers/families.ts). */
  families: Families;
  /** Clock for sessions, rate limits and elevation (tests). */
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
}

export interface Principal {
  name: string;
  role: Role;
  machines: string[] | null;
  /** The operator whose tablet a supervisor unlocked with a PIN. */
  onBehalfOf?: string;
}

interface Who {
  mode: 'open' | 'secured';
  principal: Principal | null;
  session: ConsoleSession | null;
  expired: boolean;
}

export interface Gateway {
  readonly machines: MachinesConfig;
  readonly audit: AuditLog;
  readonly usersFile: string;
  /** Connect-style middleware: handles `/api/*` and `/machines/*`, calls next() otherwise. */
  handle(req: IncomingMessage, res: ServerResponse, next: (err?: unknown) => void): void;
  /** `upgrade` listener: handles `/machines/*`, returns false (leaves the socket alone) otherwise. */
  upgrade(req: IncomingMessage, socket: Duplex, head: Buffer): boolean;
  close(): void;
}

const MAX_CLASSIFY_BODY = 1024 * 1024;
const MAX_SIM_BODY = 64 * 1024 * 1024;
const MAX_REDACT_BODY = 2 * 1024 * 1024;
const READ_METHODS = new Set(['GET', 'HEAD', 'OPTIONS']);
const TEXTISH =
  /^(text\/|application\/(json|xml|javascript|x-www-form-urlencoded|problem\+json)|[^;]*\+(json|xml))/i;

/** What the browser reports about a command it sent to a simulated machine (src/app/boot.ts). */
const clientAuditSchema = z.object({
  machine: z.string().max(40),
  method: z.string().max(10).optional(),
  path: z.string().max(2000).optional(),
  commandId: z.string().max(100).optional(),
  command: z.string().max(100).optional(),
  label: z.string().max(200).optional(),
  status: z.number().int().min(0).max(999).optional(),
  ok: z.boolean().optional(),
  result: z.string().max(500).optional(),
  error: z.string().max(500).optional(),
});

const loginSchema = z.object({ name: z.string().min(1).max(64), password: z.string().min(1).max(1024) });
const elevateSchema = z.object({ name: z.string().min(1).max(64), pin: z.string().min(1).max(64) });

function envNumber(env: NodeJS.ProcessEnv, key: string): number | undefined {
  const v = env[key];
  if (!v) return undefined;
  const n = Number(v);
  return Number.isFinite(n) && n > 0 ? n : undefined;
}

/** A hash of nothing in particular: compared against when the user does not exist (same timing). */
let dummyHash: string | null = null;
function dummy(): string {
  dummyHash ??= bcrypt.hashSync(randomBytes(16).toString('hex'), 10);
  return dummyHash;
}

/**
 * A redirect to the controller itself (absolute URL or absolute path) becomes the same place
 * under `/machines/<id>`, so the browser stays on the console's origin. Relative redirects
 * already resolve under `/machines/<id>`; redirects elsewhere are left alone.
 */
export function rewriteLocation(location: string, target: URL, id: string): string {
  const basePath = target.pathname.replace(/\/+$/, '');
  const absolute = /^[a-z][a-z0-9+.-]*:/i.test(location) || location.startsWith('//');
  if (!absolute && !location.startsWith('/')) return location;
  let u: URL;
  try {
    u = new URL(location, target.origin);
  } catch {
    return location;
  }
  if (u.origin !== target.origin) return location;
  let p = u.pathname;
  if (basePath && (p === basePath || p.startsWith(`${basePath}/`))) p = p.slice(basePath.length) || '/';
  return `/machines/${encodeURIComponent(id)}${p}${u.search}${u.hash}`;
}

export function createGateway(opts: GatewayOptions): Gateway {
  const env = opts.env ?? process.env;
  const cwd = opts.cwd ?? process.cwd();
  const now = opts.now ?? Date.now;
  const config = opts.machines ?? loadMachines({ machinesFile: opts.machinesFile, env, cwd });
  const dataDir = dataDirPath({ dataDir: opts.dataDir, env, cwd });
  const usersFile = usersFilePath({ usersFile: opts.usersFile, dataDir, env, cwd });
  const users = new UserDirectory(usersFile);
  const audit = new AuditLog(dataDir);
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
  const sessions = new SessionStore(idle, now);
  const limiter = new FailureLimiter({ ...DEFAULT_RATE_LIMIT, ...opts.rateLimit }, now);
  const byId = new Map(config.machines.map((m) => [m.id, m]));
  const secretsOf = new Map(config.machines.map((m) => [m.id, secretForms(m.secrets)]));
  const allSecrets = [...new Set(config.machines.flatMap((m) => secretForms(m.secrets)))];
  const sims = new Map<string, FaultySimulator>();
  const openSockets = new Set<WebSocket>();
  const pending = new Set<http.ClientRequest>();
  const httpAgent = new http.Agent({ keepAlive: false });
  // Controllers (TouchCut) use self-signed certificates: accepted on this agent only.
  const httpsAgent = new https.Agent({ keepAlive: false, rejectUnauthorized: false });
  let closed = false;

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
  const record = (e: Omit<AuditEntry, 'time'>): void => {
    try {
      audit.append({ ...e, time: nowIso() });
    } catch (err) {
      console.error(`shopdeck: could not write the audit log: ${String(err)}`);
    }
  };
  const scrub = (text: string): string => redact(text, allSecrets);

  // ---------------------------------------------------------------- who is asking

  function who(req: IncomingMessage, touch: boolean): Who {
    if (users.mode === 'open') {
      return {
        mode: 'open',
        principal: { name: 'anonymous', role: 'supervisor', machines: null },
        session: null,
        expired: false,
      };
    }
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
      if (sup && sup.role === 'supervisor') {
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

  // ---------------------------------------------------------------- /api

  async function api(req: IncomingMessage, res: ServerResponse, url: URL): Promise<void> {
    const method = req.method ?? 'GET';
    const route = `${method} ${url.pathname}`;
    const address = clientAddress(req);
    if (method !== 'GET' && method !== 'HEAD' && !sameOrigin(req)) {
      sendJson(res, 403, { error: 'cross-site request refused' });
      return;
    }
    switch (route) {
      case 'GET /api/session': {
        sendJson(res, 200, sessionBody(who(req, false)));
        return;
      }
      case 'POST /api/session/activity': {
        const w = who(req, true);
        sendJson(res, w.principal ? 200 : 401, sessionBody(w));
        return;
      }
      case 'POST /api/login': {
        if (users.mode === 'open') {
          sendJson(res, 400, { error: 'open mode: there are no users to log in as' });
          return;
        }
        const body = loginSchema.safeParse(await readJson(req));
        if (!body.success) {
          sendJson(res, 400, { error: 'send { "name": …, "password": … }' });
          return;
        }
        const { name, password } = body.data;
        const keys = [`user:${name}`, `addr:${address}`];
        const wait = limiter.retryAfter(keys);
        if (wait > 0) {
          record({
            type: 'login-failed',
            result: 'refused',
            user: name,
            source: 'gateway',
            address,
            error: 'too many failed logins',
          });
          sendJson(
            res,
            429,
            { error: `too many failed logins: try again in ${wait} s`, retryAfterS: wait },
            { 'Retry-After': String(wait) },
          );
          return;
        }
        const u = users.find(name);
        const ok = await checkSecret(password, u?.passwordHash ?? dummy());
        if (!u || !ok) {
          limiter.fail(keys);
          record({
            type: 'login-failed',
            result: 'failed',
            user: name,
            source: 'gateway',
            address,
            error: 'wrong name or password',
          });
          sendJson(res, 401, { error: 'wrong name or password' });
          return;
        }
        limiter.reset(`user:${name}`);
        const s = sessions.create(u.name, u.role);
        record({ type: 'login', result: 'ok', user: u.name, role: u.role, source: 'gateway', address });
        const w: Who = {
          mode: 'secured',
          principal: { name: u.name, role: u.role, machines: u.machines },
          session: s,
          expired: false,
        };
        sendJson(res, 200, sessionBody(w), { 'Set-Cookie': cookie(req, s.token) });
        return;
      }
      case 'POST /api/logout': {
        const token = parseCookies(req.headers.cookie)[SESSION_COOKIE];
        const s = sessions.get(token, false);
        if (token) sessions.delete(token);
        if (s && !('expired' in s))
          record({ type: 'logout', result: 'ok', user: s.user, source: 'gateway', address });
        sendJson(
          res,
          200,
          { mode: users.mode, user: null, idleTimeoutS: null, elevation: null, expired: false },
          {
            'Set-Cookie': cookie(req, '', 0),
          },
        );
        return;
      }
      case 'POST /api/elevate': {
        const w = who(req, true);
        if (w.mode === 'open') {
          sendJson(res, 400, { error: 'open mode: everyone already has every role' });
          return;
        }
        if (!w.session) {
          needLogin(res, w);
          return;
        }
        const body = elevateSchema.safeParse(await readJson(req));
        if (!body.success) {
          sendJson(res, 400, { error: 'send { "name": …, "pin": … }' });
          return;
        }
        const { name, pin } = body.data;
        const keys = [`pin:${name}`, `addr:${address}`];
        const wait = limiter.retryAfter(keys);
        const onBehalfOf = w.session.user;
        if (wait > 0) {
          record({
            type: 'elevate-failed',
            result: 'refused',
            user: name,
            onBehalfOf,
            source: 'gateway',
            address,
            error: 'too many failed PINs',
          });
          sendJson(
            res,
            429,
            { error: `too many failed PINs: try again in ${wait} s`, retryAfterS: wait },
            { 'Retry-After': String(wait) },
          );
          return;
        }
        const sup = users.find(name);
        const ok = await checkSecret(pin, sup?.pinHash ?? dummy());
        if (!sup || !ok || sup.role !== 'supervisor' || !sup.pinHash) {
          limiter.fail(keys);
          record({
            type: 'elevate-failed',
            result: 'failed',
            user: name,
            onBehalfOf,
            source: 'gateway',
            address,
            error: 'wrong supervisor or PIN',
          });
          sendJson(res, 401, { error: 'wrong supervisor name or PIN' });
          return;
        }
        limiter.reset(`pin:${name}`);
        w.session.elevation = { supervisor: sup.name, until: now() + elevationMs };
        record({
          type: 'elevate',
          result: 'ok',
          user: sup.name,
          onBehalfOf,
          role: 'supervisor',
          source: 'gateway',
          address,
        });
        sendJson(res, 200, sessionBody(who(req, false)));
        return;
      }
      case 'DELETE /api/elevate': {
        const w = who(req, false);
        if (w.session?.elevation) {
          record({
            type: 'elevate-end',
            result: 'ok',
            user: w.session.elevation.supervisor,
            onBehalfOf: w.session.user,
            source: 'gateway',
            address,
          });
          w.session.elevation = null;
        }
        sendJson(res, w.session ? 200 : 401, sessionBody(who(req, false)));
        return;
      }
      case 'GET /api/machines': {
        const w = who(req, false);
        if (!w.principal) {
          needLogin(res, w);
          return;
        }
        const p = w.principal;
        const machines = config.machines.filter((m) => mayUseMachine(p, m.id)).map(machineInfo);
        // `demo`: the built-in demo fleet (no machines file): the console starts demo jobs.
        sendJson(res, 200, {
          machines,
          demo: config.file === null && config.machines.every((m) => m.simulated),
        });
        return;
      }
      case 'GET /api/audit':
      case 'GET /api/audit.csv': {
        const w = who(req, false);
        if (!w.principal) {
          needLogin(res, w);
          return;
        }
        if (!roleAtLeast(w.principal.role, 'supervisor')) {
          sendJson(res, 403, { error: 'the audit log is for supervisors', needs: 'supervisor' });
          return;
        }
        const q = { ...auditQueryFrom(url.searchParams), machines: w.principal.machines };
        if (url.pathname.endsWith('.csv')) {
          const csv = toCsv(audit.filtered(q));
          res.writeHead(200, {
            'Content-Type': 'text/csv; charset=utf-8',
            'Content-Disposition': 'attachment; filename="shopdeck-audit.csv"',
            'Cache-Control': 'no-store',
          });
          res.end(csv);
        } else {
          sendJson(res, 200, audit.query(q));
        }
        return;
      }
      case 'POST /api/audit/client': {
        const w = who(req, true);
        if (!w.principal) {
          needLogin(res, w);
          return;
        }
        const body = clientAuditSchema.safeParse(await readJson(req));
        if (!body.success) {
          sendJson(res, 400, { error: 'not an audit record' });
          return;
        }
        const b = body.data;
        const m = byId.get(b.machine);
        if (!m || !m.simulated || !mayUseMachine(w.principal, m.id)) {
          sendJson(res, 403, { error: 'the browser may only record commands it sent to simulated machines' });
          return;
        }
        const ok = b.ok ?? (b.status !== undefined && b.status < 400);
        record({
          type: 'command',
          result: ok ? 'ok' : 'error',
          user: w.principal.name,
          onBehalfOf: w.principal.onBehalfOf,
          source: 'client',
          machine: m.id,
          method: b.method?.toUpperCase(),
          path: b.path === undefined ? undefined : scrub(b.path),
          commandId: b.commandId ?? b.command,
          label: b.label,
          status: b.status,
          detail: b.result === undefined ? undefined : scrub(b.result),
          error: b.error === undefined ? undefined : scrub(b.error),
          address,
        });
        sendJson(res, 201, { ok: true });
        return;
      }
      case 'GET /api/discover/xtool': {
        const w = who(req, false);
        if (!w.principal) {
          needLogin(res, w);
          return;
        }
        if (!roleAtLeast(w.principal.role, 'supervisor')) {
          sendJson(res, 403, {
            error: 'finding lasers on the network is for supervisors',
            needs: 'supervisor',
          });
          return;
        }
        const d = opts.discovery ?? {};
        const result = await discoverXtool({
          broadcast: d.broadcast ?? env.SHOPDECK_DISCOVERY_BROADCAST ?? '255.255.255.255',
          udpPort: d.udpPort ?? envNumber(env, 'SHOPDECK_DISCOVERY_UDP_PORT') ?? 20000,
          tcpPort: d.tcpPort ?? envNumber(env, 'SHOPDECK_DISCOVERY_TCP_PORT') ?? 20001,
          listenUdpPort: d.listenUdpPort,
          listenMs: d.listenMs ?? 2000,
          bindAddress: d.bindAddress,
        });
        sendJson(res, 200, result);
        return;
      }
      default:
        sendJson(res, 404, { error: `no such endpoint: ${method} ${url.pathname}` });
    }
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

  type Verdict =
    { ok: true; principal: Principal } | { ok: false; status: number; body: Record<string, unknown> };

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

  // ---------------------------------------------------------------- /machines (HTTP)

  function simulatorFor(m: MachineEntry): FaultySimulator | null {
    let sim = sims.get(m.id);
    if (sim) return sim;
    const fam = opts.families[m.kind];
    if (!fam) return null;
    sim = new FaultySimulator(fam.createSimulator({ id: m.id, name: m.name }));
    sims.set(m.id, sim);
    return sim;
  }

  async function proxy(
    req: IncomingMessage,
    res: ServerResponse,
    m: MachineEntry,
    rest: string,
  ): Promise<void> {
    const method = (req.method ?? 'GET').toUpperCase();
    const address = clientAddress(req);
    const t = splitTarget(rest);
    if ('error' in t) {
      sendJson(res, 400, { error: t.error });
      return;
    }
    const fam = opts.families[m.kind];
    let body: Buffer | null = null;
    const needsBody = fam?.accessNeedsBody?.(method, t.path) ?? false;
    if (needsBody) {
      try {
        body = await readBody(req, MAX_CLASSIFY_BODY);
      } catch (e) {
        if (e instanceof BodyTooLarge) {
          sendJson(res, 413, { error: `request body larger than ${MAX_CLASSIFY_BODY} bytes` });
          return;
        }
        throw e;
      }
    }
    const decision = classify(m, { method, path: t.path, query: t.query, body: body?.toString('utf8') });
    const isCommand = !READ_METHODS.has(method) || decision.command;
    const w = who(req, isCommand);
    const auditPath = scrub(t.path + (t.rawQuery ? `?${t.rawQuery}` : ''));
    const commandId =
      typeof req.headers['x-shopdeck-command'] === 'string'
        ? req.headers['x-shopdeck-command'].slice(0, 100)
        : undefined;
    const base = {
      machine: m.id,
      method,
      path: auditPath,
      commandId,
      label: decision.label,
      address,
      source: 'gateway' as const,
    };
    const v = authorize(w, m, decision);
    if (!v.ok) {
      if (v.status === 403 || isCommand) {
        record({
          ...base,
          type: 'refused',
          result: 'refused',
          user: w.principal?.name ?? 'nobody',
          onBehalfOf: w.principal?.onBehalfOf,
          role: decision.role,
          error: String(v.body.error),
        });
      }
      req.resume();
      sendJson(res, v.status, v.body);
      return;
    }
    const done = (r: { status?: number; error?: string }): void => {
      if (!isCommand) return;
      const ok = r.status !== undefined && r.status < 400;
      record({
        ...base,
        type: 'command',
        result: ok ? 'ok' : 'error',
        user: v.principal.name,
        onBehalfOf: v.principal.onBehalfOf,
        ...r,
      });
    };

    const headers = forwardRequestHeaders(req.headers);
    const query = new URLSearchParams(t.query);
    const before = query.toString();
    fam?.gateway?.injectSecrets?.({ method, path: t.path, headers, query }, m.secrets);
    const qs = query.toString() === before ? t.rawQuery : query.toString();
    const pathAndQuery = t.path + (qs ? `?${qs}` : '');

    if (m.simulated) {
      await answerFromSimulator(req, res, m, method, pathAndQuery, headers, body, done);
      return;
    }
    if (!m.url) {
      sendJson(res, 502, { error: `machine ${m.id} has no url` });
      return;
    }
    forward(req, res, m, m.url, method, pathAndQuery, headers, body, done);
  }

  async function answerFromSimulator(
    req: IncomingMessage,
    res: ServerResponse,
    m: MachineEntry,
    method: string,
    pathAndQuery: string,
    headers: Record<string, string>,
    buffered: Buffer | null,
    done: (r: { status?: number; error?: string }) => void,
  ): Promise<void> {
    const sim = simulatorFor(m);
    if (!sim) {
      req.resume();
      sendJson(res, 503, { error: `no simulator for ${m.kind}: the family is not registered` });
      done({ status: 503 });
      return;
    }
    let body: Buffer | null = buffered;
    if (!body && method !== 'GET' && method !== 'HEAD') body = await readBody(req, MAX_SIM_BODY);
    const request = new Request(`http://${m.id}.sim${pathAndQuery}`, {
      method,
      headers,
      body: body && method !== 'GET' && method !== 'HEAD' ? new Uint8Array(body) : undefined,
    });
    let answer: Response;
    try {
      answer = await sim.fetch(request, pathAndQuery);
    } catch (e) {
      done({ error: e instanceof SimDropped ? 'connection dropped (simulated)' : String(e) });
      if (e instanceof SimDropped) res.destroy();
      else sendJson(res, 502, { error: `simulator failed: ${e instanceof Error ? e.message : String(e)}` });
      return;
    }
    const out: Record<string, string> = {};
    answer.headers.forEach((value, key) => {
      const k = key.toLowerCase();
      if (
        k !== 'set-cookie' &&
        k !== 'content-length' &&
        k !== 'www-authenticate' &&
        k !== 'content-encoding'
      )
        out[k] = value;
    });
    const buf = Buffer.from(await answer.arrayBuffer());
    res.writeHead(answer.status, { ...out, 'Content-Length': String(buf.length) });
    res.end(method === 'HEAD' ? undefined : buf);
    done({ status: answer.status });
  }

  function forward(
    req: IncomingMessage,
    res: ServerResponse,
    m: MachineEntry,
    target: URL,
    method: string,
    pathAndQuery: string,
    headers: Record<string, string>,
    body: Buffer | null,
    done: (r: { status?: number; error?: string }) => void,
  ): void {
    const isHttps = target.protocol === 'https:';
    const basePath = target.pathname.replace(/\/+$/, '');
    const forms = secretsOf.get(m.id) ?? [];
    if (body) headers['content-length'] = String(body.length);
    else if (req.headers['content-length']) headers['content-length'] = req.headers['content-length'];
    else if (req.headers['transfer-encoding']) headers['transfer-encoding'] = 'chunked';
    const upstream = (isHttps ? https : http).request({
      protocol: target.protocol,
      hostname: target.hostname.replace(/^\[|\]$/g, ''),
      port: target.port || (isHttps ? 443 : 80),
      method,
      path: basePath + pathAndQuery,
      headers: { ...headers, host: target.host },
      agent: isHttps ? httpsAgent : httpAgent,
    });
    pending.add(upstream);
    let timedOut = false;
    let finished = false;
    const finish = (r: { status?: number; error?: string }): void => {
      if (finished) return;
      finished = true;
      pending.delete(upstream);
      done(r);
    };
    upstream.setTimeout(timeoutMs, () => {
      timedOut = true;
      upstream.destroy(new Error(`the controller did not answer within ${timeoutMs} ms`));
    });
    upstream.on('error', (e) => {
      const msg = redact(e.message, forms);
      finish({ error: msg });
      if (!res.headersSent) {
        sendJson(res, timedOut ? 504 : 502, {
          error: timedOut ? `timeout: ${msg}` : `cannot reach the controller of ${m.id}: ${msg}`,
        });
      } else {
        res.destroy();
      }
    });
    res.on('close', () => {
      if (!res.writableFinished) upstream.destroy();
    });
    upstream.on('response', (up) => {
      const status = up.statusCode ?? 502;
      const outHeaders = forwardResponseHeaders(up.headers);
      for (const [k, v] of Object.entries(outHeaders)) {
        outHeaders[k] = Array.isArray(v) ? v.map((x) => redact(x, forms)) : redact(v, forms);
      }
      const location = outHeaders.location;
      if (typeof location === 'string') outHeaders.location = rewriteLocation(location, target, m.id);
      const type = String(up.headers['content-type'] ?? '');
      const encoded = up.headers['content-encoding'] && up.headers['content-encoding'] !== 'identity';
      const length = Number(up.headers['content-length'] ?? NaN);
      const check =
        forms.length > 0 && !encoded && (type === '' || TEXTISH.test(type)) && !(length > MAX_REDACT_BODY);
      if (!check) {
        res.writeHead(
          status,
          up.headers['content-length']
            ? { ...outHeaders, 'content-length': up.headers['content-length'] }
            : outHeaders,
        );
        up.pipe(res);
        up.on('end', () => finish({ status }));
        up.on('error', (e) => finish({ status, error: redact(e.message, forms) }));
        return;
      }
      const chunks: Buffer[] = [];
      let size = 0;
      let streaming = false;
      up.on('data', (c: Buffer) => {
        if (streaming) return;
        size += c.length;
        chunks.push(c);
        if (size > MAX_REDACT_BODY) {
          // Too big to check: send what we have (checked) and stream the rest as is.
          streaming = true;
          up.pause();
          res.writeHead(status, outHeaders);
          res.write(redact(Buffer.concat(chunks).toString('utf8'), forms));
          up.pipe(res);
          up.resume();
        }
      });
      up.on('end', () => {
        if (!streaming) {
          const text = Buffer.concat(chunks);
          const clean = Buffer.from(redact(text.toString('utf8'), forms), 'utf8');
          const same = clean.length === text.length && clean.equals(text);
          res.writeHead(status, {
            ...outHeaders,
            'content-length': String(same ? text.length : clean.length),
          });
          res.end(same ? text : clean);
        }
        finish({ status });
      });
      up.on('error', (e) => finish({ status, error: redact(e.message, forms) }));
    });
    if (body) upstream.end(body);
    else if (method === 'GET' || method === 'HEAD') {
      req.resume();
      upstream.end();
    } else req.pipe(upstream);
  }

  // ---------------------------------------------------------------- /machines (WebSocket)

  function bridge(client: WebSocket, upstream: WebSocket): void {
    openSockets.add(client);
    openSockets.add(upstream);
    const closeCode = (code: number): number | undefined =>
      (code >= 1000 && code <= 1003) || (code >= 1007 && code <= 1014) || (code >= 3000 && code <= 4999)
        ? code
        : undefined;
    const pass = (from: WebSocket, to: WebSocket) => {
      from.on('message', (data: RawData, isBinary: boolean) => {
        if (to.readyState === WebSocket.OPEN) to.send(data, { binary: isBinary });
      });
      from.on('close', (code: number, reason: Buffer) => {
        openSockets.delete(from);
        if (to.readyState === WebSocket.OPEN || to.readyState === WebSocket.CONNECTING) {
          const c = closeCode(code);
          if (code === 1006) to.terminate();
          else if (c === undefined) to.close();
          else to.close(c, reason.toString('utf8').slice(0, 120));
        }
      });
      from.on('error', () => {
        openSockets.delete(from);
        to.terminate();
      });
    };
    pass(client, upstream);
    pass(upstream, client);
  }

  function upgrade(req: IncomingMessage, socket: Duplex, head: Buffer): boolean {
    const url = req.url ?? '/';
    const match = /^\/machines\/([^/?#]+)(.*)$/.exec(url);
    if (!match) return false;
    let id = '';
    try {
      id = decodeURIComponent(match[1] ?? '');
    } catch {
      id = '';
    }
    void upgradeMachine(req, socket, head, id, match[2] ?? '').catch((e: unknown) => {
      rejectUpgrade(socket, 502, { error: scrub(e instanceof Error ? e.message : String(e)) });
    });
    return true;
  }

  async function upgradeMachine(
    req: IncomingMessage,
    socket: Duplex,
    head: Buffer,
    id: string,
    rest: string,
  ): Promise<void> {
    socket.on('error', () => socket.destroy());
    const address = clientAddress(req);
    if (closed) return rejectUpgrade(socket, 503, { error: 'the gateway is shutting down' });
    if (!hostAllowed(req)) return rejectUpgrade(socket, 403, { error: 'this host name is not allowed' });
    if (!sameOrigin(req)) return rejectUpgrade(socket, 403, { error: 'cross-site WebSocket refused' });
    const m = byId.get(id);
    if (!m) return rejectUpgrade(socket, 404, { error: `no machine "${id}" in the machines file` });
    const t = splitTarget(rest || '/');
    if ('error' in t) return rejectUpgrade(socket, 400, { error: t.error });
    const decision = classify(m, { method: 'GET', path: t.path, query: t.query, websocket: true });
    const w = who(req, decision.command);
    const auditPath = scrub(t.path + (t.rawQuery ? `?${t.rawQuery}` : ''));
    const base = {
      machine: m.id,
      method: 'WS',
      path: auditPath,
      label: decision.label,
      address,
      source: 'gateway' as const,
    };
    const v = authorize(w, m, decision);
    if (!v.ok) {
      if (v.status === 403 || decision.command) {
        record({
          ...base,
          type: 'refused',
          result: 'refused',
          user: w.principal?.name ?? 'nobody',
          role: decision.role,
          error: String(v.body.error),
        });
      }
      return rejectUpgrade(socket, v.status, v.body);
    }
    const audited = (r: { status?: number; error?: string }): void => {
      if (decision.command) {
        record({
          ...base,
          type: 'command',
          result: r.error ? 'error' : 'ok',
          user: v.principal.name,
          onBehalfOf: v.principal.onBehalfOf,
          ...r,
        });
      }
    };
    const fam = opts.families[m.kind];
    const offered = String(req.headers['sec-websocket-protocol'] ?? '')
      .split(',')
      .map((s) => s.trim())
      .filter(Boolean);

    if (m.simulated) {
      const sim = simulatorFor(m);
      if (!sim) return rejectUpgrade(socket, 503, { error: `no simulator for ${m.kind}` });
      const wss = new WebSocketServer({ noServer: true, clientTracking: false, perMessageDeflate: false });
      wss.handleUpgrade(req, socket, head, (client) => {
        openSockets.add(client);
        audited({ status: 101 });
        bridgeSimSocket(client, sim, t.path + (t.rawQuery ? `?${t.rawQuery}` : ''), () =>
          openSockets.delete(client),
        );
      });
      return;
    }

    let baseUrl: string;
    if (m.wsUrl) {
      baseUrl = `${m.wsUrl.protocol}//${m.wsUrl.host}${m.wsUrl.pathname.replace(/\/+$/, '')}`;
    } else if (m.url) {
      const port = fam?.gateway?.defaultWsPort;
      const host = port ? `${m.url.hostname}:${port}` : m.url.host;
      baseUrl = `${m.url.protocol === 'https:' ? 'wss:' : 'ws:'}//${host}${m.url.pathname.replace(/\/+$/, '')}`;
    } else {
      return rejectUpgrade(socket, 502, { error: `machine ${m.id} has no url` });
    }
    const headers = forwardRequestHeaders(req.headers);
    const query = new URLSearchParams(t.query);
    const before = query.toString();
    fam?.gateway?.injectSecrets?.({ method: 'GET', path: t.path, headers, query }, m.secrets);
    const qs = query.toString() === before ? t.rawQuery : query.toString();
    const target = baseUrl + t.path + (qs ? `?${qs}` : '');
    const forms = secretsOf.get(m.id) ?? [];
    const upstream = new WebSocket(target, offered, {
      headers,
      rejectUnauthorized: false,
      handshakeTimeout: timeoutMs,
      perMessageDeflate: false,
      followRedirects: false,
    });
    openSockets.add(upstream);
    const early: Array<{ data: RawData; isBinary: boolean }> = [];
    const collect = (data: RawData, isBinary: boolean): void => {
      early.push({ data, isBinary });
    };
    upstream.on('message', collect);
    const fail = (status: number, error: string): void => {
      openSockets.delete(upstream);
      audited({ error });
      rejectUpgrade(socket, status, { error: redact(error, forms) });
    };
    upstream.once('unexpected-response', (_r, resp) => {
      upstream.removeAllListeners('error');
      upstream.on('error', () => undefined);
      fail(502, `the controller refused the WebSocket (HTTP ${resp.statusCode ?? '?'})`);
      resp.resume();
      upstream.terminate();
    });
    upstream.once('error', (e) => {
      if (upstream.readyState !== WebSocket.OPEN) {
        const timeout = /timed out|timeout/i.test(e.message);
        fail(timeout ? 504 : 502, `cannot open the controller's WebSocket: ${e.message}`);
      }
    });
    upstream.once('open', () => {
      const wss = new WebSocketServer({
        noServer: true,
        clientTracking: false,
        perMessageDeflate: false,
        handleProtocols: () => upstream.protocol || false,
      });
      if (socket.destroyed) {
        upstream.close(1001, 'client went away');
        return;
      }
      wss.handleUpgrade(req, socket, head, (client) => {
        audited({ status: 101 });
        upstream.off('message', collect);
        for (const e of early) client.send(e.data, { binary: e.isBinary });
        bridge(client, upstream);
      });
    });
  }

  // ---------------------------------------------------------------- entry points

  function handle(req: IncomingMessage, res: ServerResponse, next: (err?: unknown) => void): void {
    const raw = req.url ?? '/';
    const isApi = raw === '/api' || raw.startsWith('/api/') || raw.startsWith('/api?');
    const machine = /^\/machines\/([^/?#]+)(.*)$/.exec(raw);
    if (!isApi && !machine) {
      next();
      return;
    }
    const run = async (): Promise<void> => {
      if (!hostAllowed(req)) {
        req.resume();
        sendJson(res, 403, { error: 'this host name is not allowed' });
        return;
      }
      if (isApi) {
        await api(req, res, new URL(raw, 'http://gateway.local'));
        return;
      }
      let id = '';
      try {
        id = decodeURIComponent(machine?.[1] ?? '');
      } catch {
        id = '';
      }
      const m = byId.get(id);
      if (!m) {
        req.resume();
        sendJson(res, 404, { error: `no machine "${id}" in the machines file` });
        return;
      }
      if (!READ_METHODS.has((req.method ?? 'GET').toUpperCase()) && !sameOrigin(req)) {
        req.resume();
        sendJson(res, 403, { error: 'cross-site request refused' });
        return;
      }
      await proxy(req, res, m, machine?.[2] || '/');
    };
    run().catch((e: unknown) => {
      const status = e instanceof SyntaxError ? 400 : e instanceof BodyTooLarge ? 413 : 500;
      if (!res.headersSent)
        sendJson(res, status, { error: scrub(e instanceof Error ? e.message : String(e)) });
      else res.destroy();
    });
  }

  function close(): void {
    closed = true;
    for (const s of openSockets) s.terminate();
    openSockets.clear();
    for (const r of pending) r.destroy();
    pending.clear();
    for (const s of sims.values()) s.dispose();
    sims.clear();
    httpAgent.destroy();
    httpsAgent.destroy();
  }

  return { machines: config, audit, usersFile, handle, upgrade, close };
}

export type { UserRecord };
