import http, { type IncomingMessage, type ServerResponse } from 'node:http';
import type { AddressInfo } from 'node:net';
import type { Duplex } from 'node:stream';
import { WebSocket, WebSocketServer, type RawData } from 'ws';
import type { FamilyDescriptor } from '../src/fleet/contract';
import type { NodeFamily } from '../src/fleet/server-part';
import { FaultySimulator, SimDropped, type Faults, type Simulator } from '../src/fleet/sim';
import type { MachineApi, MachineKind } from '../src/fleet/types';
import { readBody, sendJson } from './http-util';

/**
 * A simulator as a real HTTP + WebSocket server on 127.0.0.1, so the console can run through
 * the gateway against it exactly as against hardware (`npm run sim`, gateway tests, Playwright).
 *
 * Besides the controller's own paths, each machine's port answers:
 * - `POST /__sim/faults` `{latencyMs, drop, http5xx, malformed}` (any subset)
 * - `POST /__sim/close-sockets`
 * - `GET /__sim/controls`, `POST /__sim/control/<controlId>` (the physical world: buttons, flames)
 */

export interface SimServerOptions {
  family: FamilyDescriptor;
  id: string;
  name: string;
  host?: string;
  /** 0 (default): any free port. */
  port?: number;
  /** Port of the separate WebSocket server for families with `defaultWsPort` (0: any). */
  wsPort?: number;
  tickMs?: number;
  /** The API it simulates, where the family has more than one (Duet: `standalone`). */
  machineApi?: MachineApi;
  /** Wrap the simulator before serving it (tests). */
  simulator?: Simulator;
}

export interface SimServer {
  id: string;
  name: string;
  kind: MachineKind;
  url: string;
  /** Set when the family's socket lives on its own port. */
  wsUrl: string | null;
  sim: FaultySimulator;
  /**
   * Upstream traffic counters since start or the last `resetStats()`, over the HTTP port and the
   * separate WebSocket port (benchmarks: how much the gateway asks of a controller).
   */
  stats(): SimServerStats;
  /** Zeroes the counters; `wsMaxOpen` restarts from the sockets open now. */
  resetStats(): void;
  close(): Promise<void>;
}

export interface SimServerStats {
  /** HTTP requests answered (not `/__sim/*`, not WebSocket upgrades). */
  requests: number;
  /** TCP connections accepted (keep-alive reuse counts once). */
  connections: number;
  /** WebSockets open now. */
  wsOpen: number;
  /** WebSockets accepted. */
  wsOpened: number;
  /** Most WebSockets open at once. */
  wsMaxOpen: number;
}

/** Turns a Node request into a fetch Request for a simulator. */
/** Connects an accepted WebSocket to a simulator's socket at `path` (closes with 4404 when it has none). */
export function bridgeSimSocket(client: WebSocket, sim: Simulator, path: string, onClose: () => void): void {
  const h = sim.socket?.(path, {
    send: (d) => {
      if (client.readyState === WebSocket.OPEN) client.send(d);
    },
    close: (code, reason) => client.close(code, reason),
  });
  if (!h) {
    client.close(4404, 'no socket here');
    onClose();
    return;
  }
  client.on('message', (data: RawData) =>
    h.message(Buffer.isBuffer(data) ? data.toString('utf8') : String(data)),
  );
  client.on('close', () => {
    onClose();
    h.close();
  });
}

export async function toFetchRequest(req: IncomingMessage, origin: string): Promise<Request> {
  const method = (req.method ?? 'GET').toUpperCase();
  const headers = new Headers();
  for (const [k, v] of Object.entries(req.headers)) {
    if (v === undefined || k.startsWith(':')) continue;
    headers.set(k, Array.isArray(v) ? v.join(', ') : v);
  }
  const hasBody = method !== 'GET' && method !== 'HEAD';
  const body = hasBody ? await readBody(req, 256 * 1024 * 1024) : null;
  return new Request(origin + (req.url ?? '/'), {
    method,
    headers,
    body: body ? new Uint8Array(body) : undefined,
  });
}

export async function writeFetchResponse(
  res: ServerResponse,
  answer: Response,
  method: string,
): Promise<void> {
  const headers: Record<string, string> = {};
  answer.headers.forEach((v, k) => {
    if (k !== 'content-length' && k !== 'content-encoding' && k !== 'transfer-encoding') headers[k] = v;
  });
  const buf = Buffer.from(await answer.arrayBuffer());
  res.writeHead(answer.status, { ...headers, 'Content-Length': String(buf.length) });
  res.end(method === 'HEAD' ? undefined : buf);
}

function listen(server: http.Server, host: string, port: number): Promise<number> {
  return new Promise((resolve, reject) => {
    server.once('error', reject);
    server.listen(port, host, () => {
      server.off('error', reject);
      resolve((server.address() as AddressInfo).port);
    });
  });
}

export async function startSimServer(o: SimServerOptions): Promise<SimServer> {
  const host = o.host ?? '127.0.0.1';
  const sim = new FaultySimulator(
    o.simulator ??
      o.family.createSimulator({
        id: o.id,
        name: o.name,
        tickMs: o.tickMs,
        ...(o.machineApi ? { machineApi: o.machineApi } : {}),
      }),
  );
  const sockets = new Set<WebSocket>();
  const counts = { requests: 0, connections: 0, wsOpened: 0, wsMaxOpen: 0 };
  const wss = new WebSocketServer({ noServer: true, perMessageDeflate: false });

  async function handle(req: IncomingMessage, res: ServerResponse): Promise<void> {
    const url = req.url ?? '/';
    const method = (req.method ?? 'GET').toUpperCase();
    if (url.startsWith('/__sim/')) {
      if (method === 'POST' && url === '/__sim/faults') {
        const raw = (await readBody(req, 16 * 1024)).toString('utf8');
        const body = (raw ? JSON.parse(raw) : {}) as Partial<Record<keyof Faults, unknown>>;
        const f: Partial<Faults> = {};
        if (typeof body.latencyMs === 'number' && body.latencyMs >= 0) f.latencyMs = body.latencyMs;
        for (const k of ['drop', 'http5xx', 'malformed'] as const)
          if (typeof body[k] === 'boolean') f[k] = body[k];
        sim.setFaults(f);
        sendJson(res, 200, { faults: sim.faults });
        return;
      }
      if (method === 'POST' && url === '/__sim/close-sockets') {
        sim.closeSockets();
        sendJson(res, 200, { ok: true });
        return;
      }
      if (method === 'GET' && url === '/__sim/controls') {
        sendJson(res, 200, { controls: sim.controls().map((c) => ({ id: c.id, label: c.label })) });
        return;
      }
      const control = /^\/__sim\/control\/([^/?]+)$/.exec(url);
      if (method === 'POST' && control) {
        const c = sim.controls().find((x) => x.id === decodeURIComponent(control[1] ?? ''));
        if (!c) {
          sendJson(res, 404, { error: 'no such control' });
          return;
        }
        c.run();
        sendJson(res, 200, { ok: true, control: c.id });
        return;
      }
      sendJson(res, 404, { error: 'no such simulator endpoint' });
      return;
    }
    const request = await toFetchRequest(req, `http://${host}`);
    let answer: Response;
    try {
      answer = await sim.fetch(request, url);
    } catch (e) {
      if (e instanceof SimDropped) {
        req.socket.destroy();
        return;
      }
      throw e;
    }
    await writeFetchResponse(res, answer, method);
  }

  const onRequest = (req: IncomingMessage, res: ServerResponse): void => {
    handle(req, res).catch((e: unknown) => {
      if (!res.headersSent) sendJson(res, 500, { error: e instanceof Error ? e.message : String(e) });
      else res.destroy();
    });
  };

  const onUpgrade = (req: IncomingMessage, socket: Duplex, head: Buffer): void => {
    const path = req.url ?? '/';
    wss.handleUpgrade(req, socket, head, (client) => {
      sockets.add(client);
      counts.wsOpened++;
      counts.wsMaxOpen = Math.max(counts.wsMaxOpen, sockets.size);
      bridgeSimSocket(client, sim, path, () => sockets.delete(client));
    });
  };

  const count = (s: http.Server): void => {
    s.on('connection', () => counts.connections++);
    s.on('request', (req: IncomingMessage) => {
      if (!(req.url ?? '/').startsWith('/__sim/')) counts.requests++;
    });
  };

  const server = http.createServer(onRequest);
  server.on('upgrade', onUpgrade);
  count(server);
  const port = await listen(server, host, o.port ?? 0);
  let wsServer: http.Server | null = null;
  let wsUrl: string | null = null;
  if (o.family.gateway?.defaultWsPort) {
    wsServer = http.createServer((_req, res) => sendJson(res, 426, { error: 'WebSocket only' }));
    wsServer.on('upgrade', onUpgrade);
    count(wsServer);
    const wsPort = await listen(wsServer, host, o.wsPort ?? 0);
    wsUrl = `ws://${host}:${wsPort}`;
  }

  const closeServer = (s: http.Server): Promise<void> =>
    new Promise((resolve) => {
      s.close(() => resolve());
      s.closeAllConnections();
    });

  return {
    id: o.id,
    name: o.name,
    kind: o.family.kind,
    url: `http://${host}:${port}`,
    wsUrl,
    sim,
    stats: () => ({ ...counts, wsOpen: sockets.size }),
    resetStats() {
      counts.requests = 0;
      counts.connections = 0;
      counts.wsOpened = 0;
      counts.wsMaxOpen = sockets.size;
    },
    async close() {
      for (const s of sockets) s.terminate();
      sockets.clear();
      sim.dispose();
      await closeServer(server);
      if (wsServer) await closeServer(wsServer);
    },
  };
}

export interface SimFleet {
  servers: SimServer[];
  /** A machines file pointing at the servers. */
  machinesFile: {
    machines: Array<{ id: string; name: string; kind: MachineKind; url: string; wsUrl?: string }>;
  };
  close(): Promise<void>;
}

/** One simulated machine per registered family, and its `simVariants` (`npm run sim`). */
export async function startSimFleet(
  families: Partial<Record<MachineKind, NodeFamily>>,
  opts: { host?: string; basePort?: number; tickMs?: number } = {},
): Promise<SimFleet> {
  const servers: SimServer[] = [];
  let next = opts.basePort ?? 0;
  try {
    const list: Array<{ fam: FamilyDescriptor; id: string; name: string; machineApi?: MachineApi }> = [];
    for (const fam of Object.values(families)) {
      if (!fam) continue;
      list.push({ fam, id: `sim-${fam.kind}`, name: `Simulated ${fam.label}` });
      for (const v of fam.simVariants ?? [])
        list.push({ fam, id: v.id, name: `Simulated ${v.label}`, machineApi: v.machineApi });
    }
    for (const { fam, id, name, machineApi } of list) {
      const port = next;
      const wsPort = next ? next + 1 : 0;
      if (next) next += 2;
      servers.push(
        await startSimServer({
          family: fam,
          id,
          name,
          host: opts.host,
          port,
          wsPort,
          tickMs: opts.tickMs,
          ...(machineApi ? { machineApi } : {}),
        }),
      );
    }
  } catch (e) {
    await Promise.all(servers.map((s) => s.close()));
    throw e;
  }
  return {
    servers,
    machinesFile: {
      machines: servers.map((s) => ({
        id: s.id,
        name: s.name,
        kind: s.kind,
        url: s.url,
        ...(s.wsUrl ? { wsUrl: s.wsUrl } : {}),
      })),
    },
    async close() {
      await Promise.all(servers.map((s) => s.close()));
    },
  };
}
