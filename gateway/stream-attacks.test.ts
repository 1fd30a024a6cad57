import { createHash } from 'node:crypto';
import http from 'node:http';
import type { AddressInfo } from 'node:net';
import type { Duplex } from 'node:stream';
import { monitorEventLoopDelay } from 'node:perf_hooks';
import { afterEach, describe, expect, it } from 'vitest';
import type { WebSocket } from 'ws';
import { families } from '../src/controllers/families';
import type { MachineEntry } from './machines';
import { gatewayFor, login, openWs, stubEntry, stubFor, user, type Cleanups } from './test-util';

/**
 * Attacks on the controllers' sockets through the real gateway, on real sockets (issue 31,
 * findings 12 and 13): a viewer who opens sockets on many paths and query strings, and a
 * controller that sends 20,000 frames at once.
 */

const cleanups: Cleanups = [];
afterEach(async () => {
  for (const c of cleanups.splice(0).reverse()) await c();
});

const sleep = (ms: number): Promise<void> => new Promise((r) => setTimeout(r, ms));
async function until(what: string, ok: () => boolean, ms = 10_000): Promise<void> {
  const end = Date.now() + ms;
  while (!ok()) {
    if (Date.now() > end) throw new Error(`timed out waiting for ${what}`);
    await sleep(10);
  }
}

/** An unmasked server text frame (RFC 6455), for writing thousands at once. */
function textFrame(s: string): Buffer {
  const p = Buffer.from(s, 'utf8');
  if (p.length > 125) throw new Error('short frames only');
  return Buffer.concat([Buffer.from([0x81, p.length]), p]);
}

interface FakeController {
  url: string;
  /** Every WebSocket upgrade that reached it: its request target. */
  upgrades: string[];
  /** The raw sockets of accepted upgrades. */
  sockets: Duplex[];
  /** HTTP requests that reached it. */
  requests: string[];
}

/**
 * A controller (xTool HTTP and its :8081 socket, a Prunt's HTTP) that accepts every WebSocket
 * by hand, so a test can write 20,000 frames in one write without the test's own cost counting.
 */
async function fakeController(): Promise<FakeController> {
  const c: FakeController = { url: '', upgrades: [], sockets: [], requests: [] };
  const server = http.createServer((req, res) => {
    c.requests.push(req.url ?? '');
    res.writeHead(200, { 'Content-Type': 'application/json' });
    res.end('{"ok":true}');
  });
  server.on('upgrade', (req, socket: Duplex) => {
    c.upgrades.push(req.url ?? '');
    const accept = createHash('sha1')
      .update(`${String(req.headers['sec-websocket-key'])}258EAFA5-E914-47DA-95CA-C5AB0DC85B11`)
      .digest('base64');
    socket.write(
      `HTTP/1.1 101 Switching Protocols\r\nUpgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Accept: ${accept}\r\n\r\n`,
    );
    socket.on('error', () => undefined);
    socket.on('data', () => undefined); // the gateway's frames (a close) are read and ignored
    c.sockets.push(socket);
  });
  await new Promise<void>((r) => server.listen(0, '127.0.0.1', () => r()));
  c.url = `http://127.0.0.1:${(server.address() as AddressInfo).port}`;
  cleanups.push(async () => {
    for (const s of c.sockets) s.destroy();
    server.closeAllConnections();
    await new Promise<void>((r) => server.close(() => r()));
  });
  return c;
}

function machine(id: string, kind: MachineEntry['kind'], url: string | null): MachineEntry {
  return {
    id,
    name: id,
    kind,
    simulated: url === null,
    url: url ? new URL(url) : null,
    wsUrl: url ? new URL(url.replace(/^http/, 'ws')) : null,
    secrets: { password: 'socket-attack-secret' },
  };
}

const PW = 'stream-attack-pass';

/** Opens a socket as the viewer: its first frame not awaited; the HTTP status when refused. */
async function tryOpen(url: string, cookie: string): Promise<{ status: number; ws?: WebSocket }> {
  try {
    const w = await openWs(url, { Cookie: cookie }, false);
    return { status: 101, ws: w.ws };
  } catch (e) {
    return { status: (e as { status?: number }).status ?? 0 };
  }
}

describe('finding 12: a viewer cannot open controller sockets at will', () => {
  it('30 viewer sockets on many paths and query strings: one upstream per declared path, the rest refused before the controller', async () => {
    const ctrl = await fakeController();
    const gw = await gatewayFor(
      cleanups,
      [
        machine('laser', 'xtool', ctrl.url),
        machine('printer', 'prunt', ctrl.url),
        machine('sim-laser', 'xtool', null),
      ],
      { families, users: [user('vic', 'viewer', PW)] },
    );
    const cookie = await login(gw.url, 'vic', PW);
    const ws = (id: string, p: string): string => `ws://${gw.host}/machines/${id}${p}`;
    const declared = [
      '/',
      '/?a=1',
      '/?a=2',
      '/?sessionKey=x',
      '/?x=1&y=2',
      '//',
      '/?',
      '/?cache=' + 'z'.repeat(200),
      '/?a=1&a=2',
      '/./',
    ];
    const undeclared = [
      '/ws',
      '/socket',
      '/status',
      '/x',
      '/%2F',
      '/progress',
      '/a/b',
      '/..%2Fws',
      '/live',
      '/%20',
    ];
    const sockets: WebSocket[] = [];
    const refused: number[] = [];
    for (const p of declared) {
      const r = await tryOpen(ws('laser', p), cookie);
      if (r.ws) sockets.push(r.ws);
      else refused.push(r.status);
    }
    const undeclaredStatus: number[] = [];
    for (const p of undeclared) {
      const r = await tryOpen(ws('laser', p), cookie);
      if (r.ws) sockets.push(r.ws);
      undeclaredStatus.push(r.status);
    }
    // Prunt: its one declared socket, with query strings, and other paths.
    const prunt = [
      '/websocket/everything',
      '/websocket/everything?a=1',
      '/websocket/everything?b=2',
      '/websocket',
      '/',
    ];
    const pruntStatus: number[] = [];
    for (const p of prunt) {
      const r = await tryOpen(ws('printer', p), cookie);
      if (r.ws) sockets.push(r.ws);
      pruntStatus.push(r.status);
    }
    // The demo fleet's simulated laser: the same rule.
    const simStatus: number[] = [];
    for (const p of ['/', '/?q=1', '/?q=2', '/other', '/ws']) {
      const r = await tryOpen(ws('sim-laser', p), cookie);
      if (r.ws) sockets.push(r.ws);
      simStatus.push(r.status);
    }
    cleanups.push(() => sockets.forEach((s) => s.terminate()));
    await sleep(100);

    // Every spelling of the declared path joins the one socket (a repeated key: 400, as over HTTP).
    expect(refused).toEqual([400]);
    expect(undeclaredStatus).toEqual(undeclared.map(() => 404));
    expect(pruntStatus).toEqual([101, 101, 101, 404, 404]);
    expect(simStatus).toEqual([101, 101, 101, 404, 404]);
    // The controller saw exactly one socket per machine and declared path, without the query.
    expect([...ctrl.upgrades].sort()).toEqual(['/', '/websocket/everything']);
    expect(gw.gw.streamStats('laser').open).toBe(1);
    expect(gw.gw.streamStats('printer').open).toBe(1);
    expect(gw.gw.streamStats('sim-laser')).toEqual({ joined: 3, open: 1 });
    // Nothing of the refused ones reached the controller over HTTP either (no session, no probe).
    expect(ctrl.requests).toEqual([]);
  });
});

describe('finding 12, every family: only the declared sockets exist', () => {
  it('the demo fleet’s simulators (open mode: every role): declared paths share one socket, every other path is refused', async () => {
    const sim = (
      id: string,
      kind: MachineEntry['kind'],
      extra: Partial<MachineEntry> = {},
    ): MachineEntry => ({
      ...machine(id, kind, null),
      ...extra,
    });
    const gw = await gatewayFor(
      cleanups,
      [
        sim('x', 'xtool'),
        sim('p', 'prunt'),
        sim('d', 'duet'),
        sim('rrf', 'duet', { api: 'standalone' }),
        sim('t', 'touchcut'),
        sim('g', 'g2core'),
      ],
      { families },
    );
    const probes: Array<[string, string, number]> = [
      ['x', '/', 101],
      ['x', '/?n=1', 101],
      ['x', '/ws', 404],
      ['p', '/websocket/everything', 101],
      ['p', '/websocket/everything?n=1', 101],
      ['p', '/websocket', 404],
      ['d', '/machine', 101],
      ['d', '/machine?sessionKey=mine', 101],
      ['d', '/machine/model', 404],
      ['rrf', '/machine', 404], // a standalone board has no socket
      ['t', '/', 404],
      ['t', '/rest/v1/status', 404],
      ['g', '/', 404],
      ['g', '/status_report', 404],
    ];
    const sockets: WebSocket[] = [];
    cleanups.push(() => sockets.forEach((w) => w.terminate()));
    const got: Array<[string, string, number]> = [];
    for (const [id, p] of probes) {
      const r = await tryOpen(`ws://${gw.host}/machines/${id}${p}`, '');
      if (r.ws) sockets.push(r.ws);
      got.push([id, p, r.status]);
    }
    expect(got).toEqual(probes);
    for (const id of ['x', 'p', 'd']) expect(gw.gw.streamStats(id)).toEqual({ joined: 2, open: 1 });
    for (const id of ['rrf', 't', 'g']) expect(gw.gw.streamStats(id)).toEqual({ joined: 0, open: 0 });
  });
});

describe('finding 12, bridged sockets: bounded per machine', () => {
  it('a family’s bridged sockets (the tests’ family: 8 a machine): the 9th is refused before the controller, a closed one frees its place', async () => {
    const stub = await stubFor(cleanups);
    const gw = await gatewayFor(cleanups, [stubEntry('p1', stub.url, { wsUrl: new URL(stub.wsUrl) })]);
    const open: WebSocket[] = [];
    cleanups.push(() => open.forEach((w) => w.terminate()));
    for (let i = 0; i < 8; i++) {
      const r = await tryOpen(`ws://${gw.host}/machines/p1/live?n=${i}`, '');
      if (r.ws) open.push(r.ws);
    }
    expect(open).toHaveLength(8);
    expect((await tryOpen(`ws://${gw.host}/machines/p1/other`, '')).status).toBe(503);
    expect(stub.wsSeen).toHaveLength(8);
    const first = open[0]!;
    await new Promise<void>((r) => {
      first.once('close', () => r());
      first.close();
    });
    await sleep(100);
    const again = await tryOpen(`ws://${gw.host}/machines/p1/live`, '');
    if (again.ws) open.push(again.ws);
    expect(again.status).toBe(101);
  });
});

describe('finding 13: a controller’s burst of frames does not stall the gateway', () => {
  it('20,000 state frames at once on one laser: another machine’s reads stay fast, the viewer gets the newest state', async () => {
    const ctrl = await fakeController();
    const gw = await gatewayFor(
      cleanups,
      [machine('laser', 'xtool', ctrl.url), machine('other', 'prunt', ctrl.url)],
      {
        families,
      },
    );
    const viewer = await openWs(`ws://${gw.host}/machines/laser/`, {}, false);
    cleanups.push(() => viewer.ws.terminate());
    const got: string[] = [];
    viewer.ws.on('message', (d) => got.push(String(d)));
    await until('the upstream socket', () => ctrl.sockets.length === 1);
    const up = ctrl.sockets[0]!;

    const burst = Buffer.concat([
      ...Array.from({ length: 20_000 }, (_, i) => textFrame(i % 2 ? 'ok:WORKING_ONLINE' : 'ok:IDLE')),
      textFrame('ok:PAUSING'),
    ]);
    const loop = monitorEventLoopDelay({ resolution: 10 });
    const latencies: number[] = [];
    let reading = true;
    const reader = (async () => {
      while (reading) {
        const t0 = performance.now();
        const r = await fetch(`${gw.url}/machines/other/status/values`);
        await r.text();
        latencies.push(performance.now() - t0);
        await sleep(5);
      }
    })();
    await sleep(100);
    loop.enable();
    up.write(burst);
    await until('the newest state', () => got.at(-1) === 'ok:PAUSING', 30_000);
    await sleep(200);
    reading = false;
    await reader;
    loop.disable();

    // Coalesced: the viewer got the newest state, not 20,001 frames (state frames supersede).
    expect(got.at(-1)).toBe('ok:PAUSING');
    expect(got.length).toBeLessThan(2000);
    // Generous bounds on a noisy 2-core machine: the gateway's own target is ~100 ms.
    const p99 = loop.percentile(99) / 1e6;
    latencies.sort((a, b) => a - b);
    const readP99 = latencies[Math.floor(latencies.length * 0.99)] ?? Infinity;
    expect(latencies.length).toBeGreaterThan(5);
    expect({ p99: p99 < 250, readP99: readP99 < 250 }).toEqual({ p99: true, readP99: true });
  }, 60_000);

  it('20,000 events at once (frames that cannot be coalesced): the flood closes the controller’s socket, the viewer is told', async () => {
    const ctrl = await fakeController();
    const gw = await gatewayFor(cleanups, [machine('laser', 'xtool', ctrl.url)], { families });
    const viewer = await openWs(`ws://${gw.host}/machines/laser/`, {}, false);
    cleanups.push(() => viewer.ws.terminate());
    const closed = new Promise<number>((r) => viewer.ws.once('close', (code) => r(code)));
    await until('the upstream socket', () => ctrl.sockets.length === 1);
    const up = ctrl.sockets[0]!;
    up.write(Buffer.concat(Array.from({ length: 20_000 }, (_, i) => textFrame(`log line ${i}`))));
    const t0 = Date.now();
    expect(await closed).toBe(1011);
    // Closed within the flood bound (5 s of too many events), not after the 20,000 went through.
    expect(Date.now() - t0).toBeLessThan(15_000);
    expect(gw.gw.streamStats('laser').open).toBe(0);
  }, 30_000);
});
