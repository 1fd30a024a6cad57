import { writeFileSync } from 'node:fs';
import https from 'node:https';
import type { IncomingMessage, ServerResponse } from 'node:http';
import type { AddressInfo, Socket } from 'node:net';
import path from 'node:path';
import type { TLSSocket } from 'node:tls';
import { X509Certificate } from 'node:crypto';
import { afterEach, beforeAll, describe, expect, it } from 'vitest';
import { touchcutFamily } from '../src/controllers/touchcut/family';
import type { FamilyDescriptor } from '../src/fleet/contract';
import {
  consoleFetch,
  gatewayFor,
  openWs,
  selfSignedCert,
  startGateway,
  stubEntry,
  startStub,
  tempDir,
  testFamily,
  type Running,
} from './test-util';
import { createContext } from './context';
import type { MachineEntry } from './machines';
import { PIN_FILE, PinStore } from './tls-pin';
import { PinnedPools } from './tls-pool';
import { upstreamRequest } from './upstream-request';

/**
 * Pinned TLS connections to a controller are kept alive between reads (tls-pool.ts), through the
 * real gateway on real sockets: handshakes counted at the controller.
 */

const cleanups: Array<() => Promise<void> | void> = [];
afterEach(async () => {
  for (const c of cleanups.splice(0).reverse()) await c();
});

interface Cert {
  key: string;
  cert: string;
  fingerprint: string;
}

let real: Cert;
let impostor: Cert;
beforeAll(() => {
  const t = tempDir();
  try {
    const make = (name: string): Cert => {
      const c = selfSignedCert(t.dir, 'kineticcutter', name);
      return { key: c.key, cert: c.cert, fingerprint: new X509Certificate(c.cert).fingerprint256 };
    };
    real = make('real');
    impostor = make('impostor');
  } finally {
    t.cleanup();
  }
});

interface Seen {
  method: string;
  url: string;
  /** Which TLS connection (1, 2, …) carried it. */
  connection: number;
}

interface Controller {
  url: string;
  port: number;
  /** TLS handshakes completed (`secureConnection`). */
  handshakes: number;
  /** TCP connections accepted (a client that refuses the certificate may leave before `secureConnection`). */
  connects: number;
  /** TLS connections open now. */
  open: number;
  seen: Seen[];
  /** Default: 200 JSON `{ ok: true, path }`. */
  respond: (req: IncomingMessage, res: ServerResponse, seen: Seen) => void;
  /** Closes the listener and every connection. */
  stop(): Promise<void>;
}

/** An HTTPS controller stand-in that counts handshakes and numbers its connections. */
async function controller(cert: Cert, port = 0): Promise<Controller> {
  const c = { handshakes: 0, connects: 0, open: 0, seen: [] as Seen[] } as unknown as Controller;
  const ids = new WeakMap<Socket, number>();
  c.respond = (req, res) => {
    res.writeHead(200, { 'Content-Type': 'application/json' });
    res.end(JSON.stringify({ ok: true, path: req.url }));
  };
  const server = https.createServer({ key: cert.key, cert: cert.cert }, (req, res) => {
    req.resume();
    req.on('end', () => {
      const s: Seen = { method: req.method ?? '', url: req.url ?? '', connection: ids.get(req.socket) ?? 0 };
      c.seen.push(s);
      c.respond(req, res, s);
    });
  });
  server.on('secureConnection', (sock: TLSSocket) => {
    c.handshakes++;
    c.open++;
    ids.set(sock, c.handshakes);
    sock.on('close', () => c.open--);
  });
  server.on('connection', () => c.connects++);
  // Its own idle timeout (and the `Keep-Alive: timeout=` it announces) far above the gateway's.
  server.keepAliveTimeout = 120_000;
  await new Promise<void>((r) => server.listen(port, '127.0.0.1', () => r()));
  c.port = (server.address() as AddressInfo).port;
  c.url = `https://127.0.0.1:${c.port}`;
  let stopped = false;
  c.stop = async () => {
    if (stopped) return;
    stopped = true;
    server.closeAllConnections();
    await new Promise<void>((r) => server.close(() => r()));
  };
  cleanups.push(c.stop);
  return c;
}

/** The test family, declaring (or not) that its controllers keep connections (`sharing.keepAlive`). */
function family(keepAlive = true): FamilyDescriptor {
  const f = testFamily('prunt');
  return { ...f, gateway: { ...f.gateway, sharing: { keepAlive, maxConcurrentReads: 8 } } };
}

function setup(machines: MachineEntry[], keepAlive = true): Promise<Running & { dataDir: string }> {
  return gatewayFor(cleanups, machines, { families: { prunt: family(keepAlive) } }).then((gw) => ({
    ...gw,
    dataDir: path.dirname(gw.usersFile),
  }));
}

async function read(gw: Running, p = '/status'): Promise<{ status: number; body: string }> {
  const r = await consoleFetch(`${gw.url}/machines/plasma${p}`);
  return { status: r.status, body: await r.text() };
}

/** Waits (real time, bounded) until `cond` holds: the controller sees a socket close a moment later. */
async function until(cond: () => boolean, what: string, ms = 5_000): Promise<void> {
  const end = Date.now() + ms;
  while (!cond()) {
    if (Date.now() > end) throw new Error(`timed out waiting for ${what}`);
    await new Promise((r) => setTimeout(r, 10));
  }
}

describe('pinned TLS connections are kept alive per machine', () => {
  it('N sequential reads through the gateway make one TLS handshake', async () => {
    const c = await controller(real);
    const gw = await setup([stubEntry('plasma', c.url)]);
    for (let i = 0; i < 6; i++) {
      const r = await read(gw, `/status?n=${i}`);
      expect(r.status, r.body).toBe(200);
      expect(JSON.parse(r.body)).toEqual({ ok: true, path: `/status?n=${i}` });
    }
    expect(c.seen).toHaveLength(6);
    expect(c.handshakes).toBe(1);
    expect(new Set(c.seen.map((s) => s.connection))).toEqual(new Set([1]));
  });

  it('a family that keeps no connections (sharing.keepAlive false) gets one per request, as before', async () => {
    const c = await controller(real);
    const gw = await setup([stubEntry('plasma', c.url)], false);
    for (let i = 0; i < 3; i++) expect((await read(gw, `/status?n=${i}`)).status).toBe(200);
    expect(c.handshakes).toBe(3);
    expect(c.seen.map((s) => s.connection)).toEqual([1, 2, 3]);
  });

  it('TouchCut: its reads share one pinned connection, the API key on each, none after an answer that closes it', async () => {
    const c = await controller(real);
    const keys: Array<string | undefined> = [];
    let close = false;
    c.respond = (req, res) => {
      keys.push(req.headers['x-touchcut-api-key'] as string | undefined);
      res.writeHead(200, {
        'Content-Type': 'application/json; charset=utf-8',
        ...(close ? { Connection: 'close' } : {}),
      });
      res.end('{"machineState":"Idle"}');
    };
    const t = tempDir();
    cleanups.push(t.cleanup);
    const gw = await startGateway({
      families: { touchcut: touchcutFamily },
      env: {},
      machines: {
        file: null,
        machines: [
          {
            id: 'plasma',
            name: 'Plasma table',
            kind: 'touchcut',
            simulated: false,
            url: new URL(c.url),
            wsUrl: null,
            secrets: { apiKey: 'TC-KEY-0123456789abcdef' },
          },
        ],
      },
      dataDir: t.dir,
      usersFile: path.join(t.dir, 'users.json'),
    });
    cleanups.push(gw.close);
    const paths = ['/rest/v1/status?units=metric', '/rest/v1/status?units=imperial', '/rest/v1/status'];
    for (const p of paths) expect((await read(gw, p)).status).toBe(200);
    expect(c.seen.map((s) => s.url)).toEqual(paths);
    expect(c.handshakes).toBe(1);
    expect(keys).toEqual(['TC-KEY-0123456789abcdef', 'TC-KEY-0123456789abcdef', 'TC-KEY-0123456789abcdef']);
    // A controller that closes after each answer (HTTP/1.0 without keep-alive): a new connection
    // each time, as before the pool.
    close = true;
    expect((await read(gw, '/rest/v1/status?units=default')).status).toBe(200);
    expect((await read(gw, '/rest/v1/monitor')).status).toBe(200);
    expect(c.seen.map((s) => s.connection)).toEqual([1, 1, 1, 1, 2]);
    expect(c.handshakes).toBe(2);
  });

  it('keeps at most 2 idle connections per machine after reads in parallel', async () => {
    const c = await controller(real);
    // The answers wait until all four reads are at the controller: four connections at once.
    const waiting: Array<() => void> = [];
    c.respond = (req, res) => {
      waiting.push(() => {
        res.writeHead(200, { 'Content-Type': 'application/json' });
        res.end('{"ok":true}');
      });
      if (waiting.length === 4) for (const w of waiting) w();
    };
    const gw = await setup([stubEntry('plasma', c.url)]);
    const all = await Promise.all([1, 2, 3, 4].map((n) => read(gw, `/status?n=${n}`)));
    expect(all.map((r) => r.status)).toEqual([200, 200, 200, 200]);
    expect(c.handshakes).toBe(4);
    await until(() => c.open <= 2, 'the pool to close what it does not keep');
    expect(c.open).toBe(2);
  });

  it('a new connection with the wrong certificate is still refused: nothing is sent to it', async () => {
    const c = await controller(real);
    const gw = await setup([stubEntry('plasma', c.url)]);
    expect((await read(gw)).status).toBe(200);
    expect(c.handshakes).toBe(1);
    // The controller goes (its kept connection with it) and an impostor takes its address.
    const port = c.port;
    await c.stop();
    const fake = await controller(impostor, port);
    const r = await read(gw);
    expect(r.status).toBe(502);
    expect((JSON.parse(r.body) as { error: string }).error).toMatch(/certificate of plasma changed/);
    expect(fake.connects).toBe(1);
    expect(fake.seen).toHaveLength(0);
  });

  it('a configured fingerprint that does not match refuses the first connection of the pool', async () => {
    const fake = await controller(impostor);
    const gw = await setup([stubEntry('plasma', fake.url, { tlsFingerprint: real.fingerprint })]);
    for (let i = 0; i < 2; i++) {
      const r = await read(gw);
      expect(r.status).toBe(502);
      expect((JSON.parse(r.body) as { error: string }).error).toMatch(/certificate of plasma changed/);
    }
    expect(fake.seen).toHaveLength(0);
    expect(fake.connects).toBe(2);
  });

  it('after a supervisor forgets the pin, the kept connection is not used again', async () => {
    const c = await controller(real);
    const gw = await setup([stubEntry('plasma', c.url)]);
    expect((await read(gw)).status).toBe(200);
    expect((await read(gw)).status).toBe(200);
    expect(c.handshakes).toBe(1);
    expect((await consoleFetch(`${gw.url}/api/tls/plasma`, { method: 'DELETE' })).status).toBe(200);
    // The kept connection is closed at once, not left for its idle timeout (4 s).
    await until(() => c.open === 0, 'the kept connection to close', 3_000);
    expect((await read(gw)).status).toBe(200);
    expect(c.handshakes).toBe(2);
    expect(c.seen.map((s) => s.connection)).toEqual([1, 1, 2]);
    // Pinned again on first use, and kept alive again.
    expect((await read(gw)).status).toBe(200);
    expect(c.handshakes).toBe(2);
  });

  it('a pin changed in the pin file is checked before a kept connection is used again', async () => {
    const c = await controller(real);
    const gw = await setup([stubEntry('plasma', c.url)]);
    expect((await read(gw)).status).toBe(200);
    expect(c.handshakes).toBe(1);
    // Someone pins another certificate by hand: the kept connection (checked against the old pin)
    // must not carry the next request; a new connection is checked against the new pin.
    writeFileSync(
      path.join(gw.dataDir, PIN_FILE),
      JSON.stringify({ plasma: { fingerprint: impostor.fingerprint, firstSeen: new Date().toISOString() } }),
    );
    const r = await read(gw);
    expect(r.status).toBe(502);
    expect((JSON.parse(r.body) as { error: string }).error).toMatch(/certificate of plasma changed/);
    expect(c.seen).toHaveLength(1);
    expect(c.connects).toBe(2);
    // A broken pin file: nothing is trusted, not even a connection kept from before.
    writeFileSync(
      path.join(gw.dataDir, PIN_FILE),
      JSON.stringify({ plasma: { fingerprint: real.fingerprint } }),
    );
    const broken = await read(gw);
    expect(broken.status).toBe(502);
    expect((JSON.parse(broken.body) as { error: string }).error).toMatch(/pin file .* is not valid/);
    expect(c.seen).toHaveLength(1);
  });

  it('a read whose kept connection the controller closed is sent once more on a new connection', async () => {
    const c = await controller(real);
    // The controller drops the kept connection just as the second request arrives on it.
    c.respond = (req, res, s) => {
      if (c.seen.length === 2 && s.connection === 1) {
        req.socket.destroy();
        return;
      }
      res.writeHead(200, { 'Content-Type': 'application/json' });
      res.end(JSON.stringify({ ok: true, path: req.url }));
    };
    const gw = await setup([stubEntry('plasma', c.url)]);
    expect((await read(gw)).status).toBe(200);
    const r = await read(gw, '/status?again=1');
    expect(r.status, r.body).toBe(200);
    expect(JSON.parse(r.body)).toEqual({ ok: true, path: '/status?again=1' });
    expect(c.seen.map((s) => [s.url, s.connection])).toEqual([
      ['/status', 1],
      ['/status?again=1', 1],
      ['/status?again=1', 2],
    ]);
  });

  it('a command goes on a new connection and is sent once, even when the controller closes it', async () => {
    const c = await controller(real);
    c.respond = (req, res) => {
      // The controller closes the connection the command came on, without an answer.
      if (req.method === 'POST') {
        req.socket.destroy();
        return;
      }
      res.writeHead(200, { 'Content-Type': 'application/json' });
      res.end(JSON.stringify({ ok: true, path: req.url }));
    };
    const gw = await setup([stubEntry('plasma', c.url)]);
    expect((await read(gw)).status).toBe(200);
    expect((await read(gw)).status).toBe(200);
    expect(c.handshakes).toBe(1);
    const r = await consoleFetch(`${gw.url}/machines/plasma/code`, {
      method: 'POST',
      body: 'M25',
      headers: { 'X-Shopdeck-Command': 'test.pause' },
    });
    expect(r.status).toBe(502);
    const body = (await r.json()) as { error: string; gateway: boolean; notConfirmed?: boolean };
    expect(body).toMatchObject({ gateway: true, notConfirmed: true });
    expect(body.error).toMatch(/plasma closed the connection/);
    // A read afterwards still works (on the kept connection), and the command was not re-sent.
    expect((await read(gw)).status).toBe(200);
    const commands = c.seen.filter((s) => s.method === 'POST');
    expect(commands).toHaveLength(1);
    // Not on the kept connection: a handshake of its own.
    expect(commands[0]?.connection).toBe(2);
    expect(c.seen.filter((s) => s.method === 'GET').map((s) => s.connection)).toEqual([1, 1, 1]);
    expect(gw.gw.audit.all().filter((e) => e.type === 'command')).toMatchObject([
      { result: 'error', machine: 'plasma' },
    ]);
  });

  it('the gateway closes its kept connections when it stops', async () => {
    const c = await controller(real);
    const t = tempDir();
    cleanups.push(t.cleanup);
    const gw = await startGateway({
      families: { prunt: family() },
      env: {},
      machines: { file: null, machines: [stubEntry('plasma', c.url)] },
      dataDir: t.dir,
      usersFile: path.join(t.dir, 'users.json'),
    });
    expect((await read(gw)).status).toBe(200);
    expect(c.open).toBe(1);
    await gw.close();
    await until(() => c.open === 0, 'the kept connection to close');
  });
});

describe("the gateway's own requests (upstream-request.ts, held sessions)", () => {
  it('reads use the kept connections (sent again once if the kept one was closed); commands and detached requests never', async () => {
    const c = await controller(real);
    c.respond = (req, res, s) => {
      // The third read finds its kept connection closed by the controller.
      if (req.url === '/status?n=2' && s.connection === 1) {
        req.socket.destroy();
        return;
      }
      if (req.method === 'POST' && req.url === '/drop') {
        req.socket.destroy();
        return;
      }
      res.writeHead(200, { 'Content-Type': 'application/json' });
      res.end(JSON.stringify({ ok: true, path: req.url }));
    };
    const t = tempDir();
    cleanups.push(t.cleanup);
    const m = stubEntry('plasma', c.url);
    const ctx = createContext({
      families: { prunt: family() },
      env: {},
      machines: { file: null, machines: [m] },
      dataDir: t.dir,
      usersFile: path.join(t.dir, 'users.json'),
    });
    cleanups.push(async () => {
      ctx.tlsPools.close();
      ctx.sessions.close();
      ctx.users.close();
      await ctx.audit.close();
    });
    for (let n = 0; n < 3; n++) {
      const a = await upstreamRequest(ctx, m, 'GET', `/status?n=${n}`);
      expect(a.status).toBe(200);
      expect(JSON.parse(a.body)).toEqual({ ok: true, path: `/status?n=${n}` });
    }
    expect(c.seen.map((s) => [s.url, s.connection])).toEqual([
      ['/status?n=0', 1],
      ['/status?n=1', 1],
      ['/status?n=2', 1],
      ['/status?n=2', 2],
    ]);
    // A command: a connection of its own, sent once even when the controller drops it.
    await expect(upstreamRequest(ctx, m, 'POST', '/drop', {}, { body: 'x' })).rejects.toMatchObject({
      code: 'ECONNRESET',
    });
    expect(c.seen.filter((s) => s.url === '/drop')).toMatchObject([{ method: 'POST', connection: 3 }]);
    // A detached read (the gateway closing): a connection of its own too.
    expect((await upstreamRequest(ctx, m, 'GET', '/bye', {}, { detached: true })).status).toBe(200);
    expect(c.seen.at(-1)).toMatchObject({ url: '/bye', connection: 4 });
    // Reads are kept on a connection again (the one a read was sent again on was its own).
    expect((await upstreamRequest(ctx, m, 'GET', '/status?n=3')).status).toBe(200);
    expect((await upstreamRequest(ctx, m, 'GET', '/status?n=4')).status).toBe(200);
    expect(c.seen.slice(-2).map((s) => s.connection)).toEqual([5, 5]);
    expect(c.handshakes).toBe(5);
  });
});

describe('PinnedPools', () => {
  it('closes a connection left idle, and checks the next one again', async () => {
    const c = await controller(real);
    const t = tempDir();
    cleanups.push(t.cleanup);
    const trusted: string[] = [];
    const pools = new PinnedPools({
      store: new PinStore(t.dir),
      timeoutMs: 5_000,
      onTrust: (m, r) => trusted.push(`${m.id} ${r.fingerprint}`),
      idleMs: 150,
    });
    cleanups.push(() => pools.close());
    const m = stubEntry('plasma', c.url);
    const get = (from = pools): Promise<number> =>
      new Promise((resolve, reject) => {
        const url = new URL(c.url);
        const req = https.request(
          { hostname: url.hostname, port: url.port, path: '/status', agent: from.agentFor(m, url) },
          (res) => {
            res.resume();
            res.on('end', () => resolve(res.statusCode ?? 0));
          },
        );
        req.on('error', reject);
        req.end();
      });
    expect(await get()).toBe(200);
    expect(await get()).toBe(200);
    expect(c.handshakes).toBe(1);
    expect(trusted).toEqual([`plasma ${real.fingerprint}`]);
    await until(() => c.open === 0, 'the idle connection to close');
    expect(await get()).toBe(200);
    expect(c.handshakes).toBe(2);
    // The same pool while the pin holds; a new one once it is forgotten.
    const pool = pools.agentFor(m, new URL(c.url));
    expect(pools.agentFor(m, new URL(c.url))).toBe(pool);
    new PinStore(t.dir).forget('plasma');
    expect(pools.agentFor(m, new URL(c.url))).not.toBe(pool);
    // Closed (the gateway stopped): a request still sent is answered, its connection not kept
    // (closed at once: the idle timeout here is far longer than the wait).
    await until(() => c.open === 0, 'the idle connection to close');
    const late = new PinnedPools({
      store: new PinStore(t.dir),
      timeoutMs: 5_000,
      onTrust: () => undefined,
      idleMs: 600_000,
    });
    late.close();
    const before = c.handshakes;
    expect(await get(late)).toBe(200);
    expect(c.handshakes).toBe(before + 1);
    await until(() => c.open === 0, 'the connection of a closed pool to close');
  });
});

describe('a certificate trusted on first use is audited, whatever connection trusted it', () => {
  it('over HTTP (a read on the pool, a command on its own connection) and over a wss: socket', async () => {
    const stub = await startStub({ key: real.key, cert: real.cert });
    cleanups.push(stub.close);
    const gw = await setup([
      stubEntry('plasma', stub.url),
      stubEntry('cmd', stub.url),
      stubEntry('live', null, { wsUrl: new URL(stub.wsUrl) }),
    ]);
    const trusts = (): Array<{ machine?: string; detail?: string }> =>
      gw.gw.audit.all().filter((e) => e.type === 'tls-trust');
    expect((await consoleFetch(`${gw.url}/machines/plasma/status`)).status).toBe(200);
    const cmd = await consoleFetch(`${gw.url}/machines/cmd/code`, {
      method: 'POST',
      body: 'M25',
      headers: { 'X-Shopdeck-Command': 'test.pause' },
    });
    expect(cmd.status).toBe(200);
    const w = await openWs(`ws://${gw.host}/machines/live/live`);
    expect(w.first).toBe('hello');
    await w.close();
    expect(
      trusts()
        .map((e) => e.machine)
        .sort(),
    ).toEqual(['cmd', 'live', 'plasma']);
    for (const e of trusts()) expect(e.detail).toContain(real.fingerprint);
  });
});
