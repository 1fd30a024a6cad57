import type { IncomingMessage, ServerResponse } from 'node:http';
import type { Duplex } from 'node:stream';
import { forceNoStore } from './answer-headers';
import { createApi } from './api';
import type { ApiRoute } from './routes/route';
import { createContext, type GatewayOptions } from './context';
import type { AuditLog } from './audit';
import { crossSiteProblem } from './csrf';
import { BodyTooLarge, clientAddress, rejectUpgrade, sendJson } from './http-util';
import type { MachinesConfig } from './machines';
import { createHttpProxy, READ_METHODS } from './proxy-http';
import { createWsProxy } from './proxy-ws';
import { createReadSocket, READ_SOCKET_PATH, type ReadSocketHeld } from './read-socket';
import { type AlarmCentre, createAlarmStores } from './alarms';
import { MachineWatch } from './watch';
import { TemperatureStore } from './temperatures';
import { StreamHubs } from './stream-hubs';
import { createHistory, type History } from './history';
import type { Webhook } from './webhook';
import { endHeldSessions } from './held-session';
import type { UserRecord } from './users';
import type { UpstreamStats } from './upstream-http';

/**
 * The gateway: the console's own server side and its trust boundary. This file assembles the
 * parts: `context.ts` (configuration, identity, access decisions, simulators), `api.ts`
 * (`/api/*`; `sim-api.ts`: `/api/sim/<id>`), `proxy-http.ts` and `proxy-ws.ts` (`/machines/<id>/*`).
 */

export type { Families, GatewayOptions, Principal } from './context';
export { rewriteLocation } from './proxy-http';

export interface Gateway {
  readonly machines: MachinesConfig;
  readonly audit: AuditLog;
  readonly usersFile: string;
  /** Connect-style middleware: handles `/api/*` and `/machines/*`, calls next() otherwise. */
  handle(req: IncomingMessage, res: ServerResponse, next: (err?: unknown) => void): void;
  /** `upgrade` listener: handles `/machines/*`, returns false (leaves the socket alone) otherwise. */
  upgrade(req: IncomingMessage, socket: Duplex, head: Buffer): boolean;
  /**
   * Shutdown: closes every bridged browser socket with 1001 (going away), so pages reconnect
   * quietly to the restarted server. Returns how many were told.
   */
  goingAway(reason: string): number;
  /** Shutdown: sockets, simulators, held sessions; starts closing the audit log (`audit.close()`). */
  close(): void;
  /** Every alarm of every machine (alarms.ts); `alarms.close()` writes what is pending. */
  readonly alarms: AlarmCentre;
  /** Alarms sent on to the webhook of the server settings. */
  readonly webhook: Webhook;
  /** The production history (history/): closed by `close()`. */
  readonly history: History;
  /** Counters of a machine's HTTP upstream (upstream-http.ts): benchmark, tests. */
  upstreamStats(id: string): UpstreamStats | null;
  /** Pages' read sockets open now (read-socket.ts). */
  readSockets(): number;
  /** Bytes the read sockets hold (gathered, unsent) and the most they held (read-socket.ts). */
  readSocketHeld(): ReadSocketHeld;
  /** Shared controller sockets of a machine (streams.ts): browser sockets joined, hubs open. */
  streamStats(id: string): { joined: number; open: number };
  /** The declared `/api/*` routes (api.ts, routes/): tests go over the table. */
  readonly apiRoutes: readonly ApiRoute[];
}

export function createGateway(opts: GatewayOptions): Gateway {
  const ctx = createContext(opts);
  const {
    config,
    usersFile,
    record,
    who,
    audit,
    byId,
    sims,
    openSockets,
    pending,
    httpAgent,
    hostAllowed,
    scrub,
    state,
  } = ctx;
  // Sessions expire and users files change without a request: re-check bridged sockets often.
  const sweep = setInterval(() => ctx.revalidateSockets(), 2000);
  sweep.unref();
  // The built-in demo fleet shows work in progress: each simulator's "demo" control (if it has
  // one) starts a job, as an operator at the machine would. Once, in the gateway: every tab sees
  // the same simulated world.
  const demoJobs = ctx.builtInDemo
    ? setTimeout(() => {
        for (const m of config.machines) ctx.startDemoJob(m);
      }, 1500)
    : null;
  demoJobs?.unref();
  // The alarm centre (alarms.ts) and the webhook that sends alarms on (settings: settings.json).
  const stores = createAlarmStores(ctx);
  const { alarms, webhook } = stores;
  const { proxy, watchRead, socketRead } = createHttpProxy(ctx);
  // The page's read socket (read-socket.ts): its polls over one WebSocket, checked as over HTTP.
  const readSocket = createReadSocket(ctx, { read: socketRead });
  // The production history (history/): jobs and states from the watch, commands from the audit records.
  const history = createHistory({
    dataDir: ctx.dataDir,
    log: ctx.log,
    now: ctx.now,
    scrub,
    machines: config.machines,
    settings: stores.settings,
    families: ctx.opts.families,
    read: watchRead,
  });
  const stopHistoryFeed = ctx.onRecord((e) => history.recorded(e));
  // The watch of each machine, by id (filled below): its summary goes with `GET /api/machines`.
  const watchById = new Map<string, MachineWatch>();
  // The last minutes of temperatures, sampled from the watch's reads (temperatures.ts), in memory.
  const temperatures = new TemperatureStore(ctx.now, scrub);
  const api = createApi(ctx, {
    ...stores,
    history,
    temperatures,
    watched: (id) => {
      const w = watchById.get(id);
      return w ? { summary: w.current, lastSeen: w.lastSeen, job: w.job } : null;
    },
    lookNow: (id) => watchById.get(id)?.lookNow(),
  });
  const { upgradeMachine, holdStream } = createWsProxy(ctx);

  // The gateway's own slow watch of every machine, viewers or not (watch.ts): job starts and ends
  // and alarms reach the log and the audit log even when no screen is open.
  const watches: MachineWatch[] = [];
  if (opts.watch !== false) {
    for (const m of config.machines) {
      const decl = ctx.hintsOf(m).sharing?.watch;
      if (!decl) continue;
      const temps = decl.temperatures
        ? temperatures.sampler(m.id, {
            decl: () => decl.temperatures,
            model: () => {
              const path = decl.stream?.path;
              return path ? (ctx.streams.find(StreamHubs.key(m.id, path, ''))?.merged ?? null) : null;
            },
          })
        : null;
      const w = new MachineWatch(m.id, decl, {
        read: async (pathAndQuery) => {
          const a = await watchRead(m, pathAndQuery);
          if (!a.gateway) temps?.polled(pathAndQuery, a.status, a.body);
          return a;
        },
        hold: (path, onFrame, onEnd) =>
          holdStream(
            m,
            path,
            (frame) => {
              onFrame(frame);
              temps?.frame(frame);
            },
            onEnd,
          ),
        // Alarm words may echo a machine's secret: scrubbed before the list, the page, the webhook.
        observe: (prev, next) => {
          alarms.observe(m, prev, {
            ...next,
            ...(next.alarms ? { alarms: next.alarms.map((a) => ({ ...a, text: scrub(a.text) })) } : {}),
          });
          history.observe(m, prev, next);
        },
        report: (e) => {
          const line = `${m.id}: ${e.what}${e.detail ? ` (${e.detail})` : ''}`;
          if (e.what === 'alarm') ctx.log.warn(line, { machine: m.id, event: e.what });
          else ctx.log.info(line, { machine: m.id, event: e.what });
          record({
            type: 'machine',
            result: e.what === 'alarm' ? 'error' : 'ok',
            user: 'gateway',
            source: 'gateway',
            machine: m.id,
            label: e.what,
            detail: scrub(e.detail),
          });
        },
      });
      watches.push(w);
      watchById.set(m.id, w);
      w.start();
    }
    temperatures.start();
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
    forceNoStore(res);
    const run = async (): Promise<void> => {
      if (!hostAllowed(req)) {
        req.resume();
        sendJson(res, 403, { error: 'this host name is not allowed' });
        return;
      }
      const method = (req.method ?? 'GET').toUpperCase();
      const crossSite = crossSiteProblem(req, READ_METHODS.has(method) ? 'read' : 'command');
      if (crossSite) {
        req.resume();
        {
          record({
            type: 'refused',
            result: 'refused',
            user: who(req, false).principal?.name ?? 'nobody',
            source: 'gateway',
            method,
            path: scrub(raw.slice(0, 300)),
            address: clientAddress(req),
            error: crossSite,
          });
        }
        sendJson(res, 403, { error: `refused: ${crossSite}`, crossSite: true });
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
      await proxy(req, res, m, machine?.[2] || '/');
    };
    run().catch((e: unknown) => {
      const status = e instanceof SyntaxError ? 400 : e instanceof BodyTooLarge ? 413 : 500;
      if (!res.headersSent)
        sendJson(res, status, { error: scrub(e instanceof Error ? e.message : String(e)) });
      else res.destroy();
    });
  }

  function upgrade(req: IncomingMessage, socket: Duplex, head: Buffer): boolean {
    const url = req.url ?? '/';
    if (url === READ_SOCKET_PATH || url.startsWith(`${READ_SOCKET_PATH}?`)) {
      readSocket.upgrade(req, socket, head);
      return true;
    }
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

  function close(): void {
    state.closed = true;
    clearInterval(sweep);
    if (demoJobs) clearTimeout(demoJobs);
    ctx.refusals.dispose();
    for (const w of watches) w.stop();
    temperatures.stop();
    stopHistoryFeed();
    history.close(); // last-seen times written, the file closed (synchronous)
    ctx.sessions.close(); // the kept sessions' file (auth.ts)
    ctx.users.close(); // the users file's folder watch (users.ts)
    webhook.close();
    alarms.close().catch((e: unknown) => {
      ctx.log.error('could not write the alarm list at shutdown', { error: String(e) });
    });
    endHeldSessions(ctx); // held controller sessions end first (held-session.ts), sims still there
    ctx.streams.closeAll(1001, 'the console is stopping'); // shared controller sockets (streams.ts)
    for (const s of openSockets) s.terminate();
    openSockets.clear();
    for (const r of pending) r.destroy();
    pending.clear();
    for (const s of sims.values()) s.dispose();
    sims.clear();
    httpAgent.destroy();
    ctx.upstream.close();
    ctx.tlsPools.close(); // kept pinned TLS connections (tls-pool.ts)
    // Queued audit entries are written and fsynced, the file closed; later ones are written
    // directly. A server awaits `audit.close()` (the same promise) before it exits.
    ctx.audit.close().catch((e: unknown) => {
      ctx.log.error('could not write the audit log at shutdown', { error: String(e) });
    });
  }

  function goingAway(reason: string): number {
    let told = readSocket.goingAway(reason);
    for (const live of [...ctx.liveSockets.values()]) {
      live.close(1001, reason);
      told++;
    }
    return told;
  }

  return {
    machines: config,
    audit,
    usersFile,
    handle,
    upgrade,
    goingAway,
    close,
    alarms,
    webhook,
    history,
    upstreamStats: ctx.upstreamStats,
    streamStats: (id: string) => ctx.streams.stats(id),
    readSockets: () => readSocket.open,
    readSocketHeld: () => readSocket.held(),
    apiRoutes: api.routes,
  };
}

export type { UserRecord };
