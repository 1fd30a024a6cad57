import { PinStore } from './tls-pin';
import { PinnedPools, trustEntry } from './tls-pool';
import { StreamHubs } from './stream-hubs';
import { secretPatterns } from './redact';
import http, { type IncomingMessage } from 'node:http';
import { isIP } from 'node:net';
import { WebSocket } from 'ws';
import { FaultySimulator } from '../src/fleet/sim';
import { AuditLog } from './audit';
import { createAuditWriter } from './audit-writer';
import { loggerFromEnv, Reachability } from './log';
import {
  DEFAULT_ELEVATION_S,
  DEFAULT_IDLE,
  DEFAULT_RATE_LIMIT,
  FailureLimiter,
  SessionStore,
  SqliteSessionFile,
  type IdleTimeouts,
} from './auth';
import type { HeldSessionHandle } from './held-types';
import { createIdentity } from './identity';
import { createMachineAccess } from './machine-access';
import { loadMachines, redact, secretForms, type MachineEntry } from './machines';
import type { GatewayOptions } from './options';
import type {
  AuditService,
  ConfigService,
  LinksService,
  LiveSocket,
  MachinesService,
  SecretsService,
  UsersService,
} from './services';
import { UserDirectory, dataDirPath, usersFilePath } from './users';
import { UpstreamHttp, type UpstreamStats } from './upstream-http';

/**
 * The gateway's context: its services (services.ts) made once from the options, shared by every
 * part. Who is asking is identity.ts, the audit writers audit-writer.ts (refusals limited in
 * refusals.ts), the machines' hints and verdicts machine-access.ts.
 */

export type { Families, GatewayOptions } from './options';
export type { CommandAudit, LiveSocket, MachineHints, Principal, Verdict, Who } from './services';
export { REFUSAL_LIMIT, RefusalAggregator, type RefusalLimit } from './refusals';

export function envNumber(env: NodeJS.ProcessEnv, key: string): number | undefined {
  const v = env[key];
  if (!v) return undefined;
  const n = Number(v);
  return Number.isFinite(n) && n > 0 ? n : undefined;
}

/** What every part of the gateway shares: the composition of its services (services.ts). */
export interface GatewayContext
  extends ConfigService, UsersService, AuditService, MachinesService, LinksService, SecretsService {}

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
  const { hintsOf, classify, authorize } = createMachineAccess(opts.families);
  const openSockets = new Set<WebSocket>();
  const pending = new Set<http.ClientRequest>();
  const httpAgent = new http.Agent({ keepAlive: false });
  // An https:/wss: controller is reached only over pinned TLS sockets (tls-pin.ts connectPinned,
  // kept for reads by tls-pool.ts), whose certificate is checked before a byte is sent.
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
  const heldSessions = new Map<string, HeldSessionHandle>();
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

  const { record, beginCommand, onRecord, refusals } = createAuditWriter(audit, log, now);
  // Kept-alive pinned TLS connections for reads, one small pool per machine (tls-pool.ts).
  const tlsPools = new PinnedPools({ store: pins, timeoutMs, onTrust: (m, r) => record(trustEntry(m, r)) });
  const scrub = (text: string): string => redact(text, allSecrets);
  const identity = createIdentity({ opts, users, sessions, record, liveSockets });
  const { who, sessionBody, cookie, mayUseMachine, needLogin, revalidateSockets } = identity;

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
    tlsPools,
    heldSessions,
    learnSecret,
  };
}
