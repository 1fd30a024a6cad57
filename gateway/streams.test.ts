import type { IncomingMessage } from 'node:http';
import type { AddressInfo } from 'node:net';
import { afterEach, describe, expect, it } from 'vitest';
import { WebSocket, WebSocketServer } from 'ws';
import { applyPatch, takeFullModel, type JsonObject } from '../src/controllers/duet/patch';
import type {
  FamilyDescriptor,
  FanoutStreamDecl,
  JsonRecord,
  ModelStreamDecl,
  SharedStreamDecl,
} from '../src/fleet/contract';
import type { MachineEntry } from './machines';
import { streamQuery } from './stream-hubs';
import { DEFAULT_STREAM_LIMITS, StreamHub, type UpstreamSocket } from './streams';
import { startGateway, tempDir, testFamily, type Running } from './test-util';

/**
 * Shared controller sockets (streams.ts), with real sockets: a controller stand-in that counts
 * its WebSockets, the real gateway, and browsers that join at different times, read slowly or
 * leave.
 */

const cleanups: Array<() => Promise<void> | void> = [];
afterEach(async () => {
  for (const c of cleanups.splice(0).reverse()) await c();
});

const sleep = (ms: number): Promise<void> => new Promise((r) => setTimeout(r, ms));

async function until(what: string, ok: () => boolean, ms = 3000): Promise<void> {
  const end = Date.now() + ms;
  while (!ok()) {
    if (Date.now() > end) throw new Error(`timed out waiting for ${what}`);
    await sleep(10);
  }
}

interface Controller {
  url: string;
  /** Upstream sockets opened so far, and open now. */
  opened: number;
  open: Set<WebSocket>;
  received: string[];
  urls: string[];
  /** Sends a frame to every open socket. */
  broadcast(frame: string): void;
  /** Greeting for a new socket. */
  greeting: (req: IncomingMessage) => string | null;
}

async function startController(
  greeting: (req: IncomingMessage) => string | null = () => null,
): Promise<Controller> {
  const wss = new WebSocketServer({ port: 0, host: '127.0.0.1' });
  await new Promise<void>((r) => wss.once('listening', () => r()));
  const c: Controller = {
    url: `http://127.0.0.1:${(wss.address() as AddressInfo).port}`,
    opened: 0,
    open: new Set(),
    received: [],
    urls: [],
    broadcast: (frame) => {
      for (const s of c.open) s.send(frame);
    },
    greeting,
  };
  wss.on('connection', (ws, req) => {
    c.opened++;
    c.open.add(ws);
    c.urls.push(req.url ?? '');
    ws.on('message', (d) => c.received.push(String(d)));
    ws.on('close', () => c.open.delete(ws));
    const g = c.greeting(req);
    if (g !== null) ws.send(g);
  });
  cleanups.push(
    () =>
      new Promise<void>((r) => {
        for (const s of wss.clients) s.terminate();
        wss.close(() => r());
      }),
  );
  return c;
}

function family(streams: SharedStreamDecl[]): FamilyDescriptor {
  const f = testFamily('prunt');
  return {
    ...f,
    gateway: { ...f.gateway, sharing: { keepAlive: false, maxConcurrentReads: 4, streams } },
  };
}

async function gateway(c: Controller, streams: SharedStreamDecl[], secrets: MachineEntry['secrets'] = {}) {
  const t = tempDir();
  cleanups.push(t.cleanup);
  const m: MachineEntry = {
    id: 'm1',
    name: 'm1',
    kind: 'prunt',
    simulated: false,
    url: new URL(c.url),
    wsUrl: null,
    secrets,
  };
  const gw: Running = await startGateway({
    machines: { file: null, machines: [m] },
    families: { prunt: family(streams) },
    dataDir: t.dir,
    env: {},
  });
  cleanups.push(gw.close);
  return { gw, ws: (p: string) => `${gw.url.replace(/^http/, 'ws')}/machines/m1${p}` };
}

const fanout = (over: Partial<FanoutStreamDecl> = {}): FanoutStreamDecl => ({
  kind: 'fanout',
  path: '/live',
  matches: (p) => p === '/live',
  graceMs: 150,
  classify: (f) =>
    f.startsWith('state:') ? { kind: 'latest', key: 'state', replay: true } : { kind: 'event' },
  fromBrowser: (f) => (/^\d+$/.test(f) ? { rateMs: Number(f) } : f === 'ping' ? { reply: 'pong' } : null),
  upstreamRate: (ms) => `rate ${ms}`,
  ...over,
});

/** A DSF-like model stream: full model, then a patch per `OK`; PING → PONG. */
const model: ModelStreamDecl = {
  kind: 'model',
  path: '/machine',
  matches: (p) => p === '/machine',
  graceMs: 150,
  full: (f) => {
    try {
      return takeFullModel(JSON.parse(f) as JsonObject).model as JsonRecord;
    } catch (e) {
      return e as Error;
    }
  },
  apply: (m, f) => {
    try {
      const r = applyPatch(m as JsonObject, JSON.parse(f) as JsonObject);
      return { model: r.model as JsonRecord, events: r.messages };
    } catch (e) {
      return e as Error;
    }
  },
  // Top-level keys that changed, whole (enough for these tests' models), and the events.
  diff: (from, to, events) => {
    const patch: JsonRecord = {};
    for (const k of Object.keys(to)) if (from[k] !== to[k]) patch[k] = to[k] ?? null;
    if (events.length) patch.messages = events;
    return JSON.stringify(patch);
  },
  first: (m) => JSON.stringify(m),
  ack: 'OK\n',
  fromBrowser: (f) => (f.trim() === 'OK' ? { ack: true } : f.trim() === 'PING' ? { reply: 'PONG\n' } : null),
};

describe('fan-out streams', () => {
  it('one upstream socket for every viewer; each gets every frame; late joiners get the last state first', async () => {
    const c = await startController();
    const { ws } = await gateway(c, [fanout()]);
    const a = await openWsNoFirst(ws('/live'));
    const b = await openWsNoFirst(ws('/live'));
    await until('one upstream', () => c.open.size === 1);
    c.broadcast('state:running');
    c.broadcast('log one');
    expect(await a.next()).toBe('state:running');
    expect(await a.next()).toBe('log one');
    expect(await b.next()).toBe('state:running');
    expect(await b.next()).toBe('log one');
    const late = await openWsNoFirst(ws('/live'));
    expect(await late.next()).toBe('state:running');
    c.broadcast('log two');
    expect(await late.next()).toBe('log two');
    expect(c.opened).toBe(1);
  });

  it('closes the upstream socket a grace period after the last viewer left, not before', async () => {
    const c = await startController();
    const { ws } = await gateway(c, [fanout({ graceMs: 300 })]);
    const a = await openWsNoFirst(ws('/live'));
    const b = await openWsNoFirst(ws('/live'));
    await until('upstream', () => c.open.size === 1);
    await a.close();
    await sleep(400);
    expect(c.open.size).toBe(1); // b still watches
    await b.close();
    await sleep(100);
    expect(c.open.size).toBe(1); // grace period
    await until('upstream closed after the grace period', () => c.open.size === 0);
    // A new viewer opens a new one.
    await openWsNoFirst(ws('/live'));
    await until('reopened', () => c.open.size === 1);
    expect(c.opened).toBe(2);
  });

  it('a browser that does not read does not delay the others, and gets the newest state only', async () => {
    const c = await startController();
    const { ws } = await gateway(c, [fanout()]);
    const slow = await openWsNoFirst(ws('/live'));
    const fast = await openWsNoFirst(ws('/live'));
    await until('upstream', () => c.open.size === 1);
    // The slow browser stops reading: its TCP window fills and the gateway's buffer for it grows.
    const raw = (slow.ws as unknown as { _socket: { pause(): void; resume(): void } })._socket;
    raw.pause();
    const big = 'x'.repeat(256 * 1024);
    const N = 80;
    for (let i = 0; i < N; i++) c.broadcast(`state:${i} ${big}`);
    // The fast browser reaches the newest state while the slow one still sleeps.
    let last = '';
    while (last !== `state:${N - 1}`) last = (await fast.next()).split(' ')[0] ?? '';
    expect(slow.take()).toBeUndefined();
    raw.resume();
    const seen: string[] = [];
    await until('the slow browser catches up with the newest state', () => {
      for (;;) {
        const f = slow.take();
        if (f === undefined) break;
        seen.push(f.split(' ')[0] ?? '');
      }
      return seen.at(-1) === `state:${N - 1}`;
    });
    // Fewer than all: the states it could not take in time were replaced by newer ones.
    expect(seen.length).toBeLessThan(N);
    expect(slow.ws.readyState).toBe(WebSocket.OPEN);
  });

  it('browser frames never reach the controller as they are: rates are merged, keep-alives answered here', async () => {
    const c = await startController();
    const { ws } = await gateway(c, [fanout()]);
    const a = await openWsNoFirst(ws('/live'));
    const b = await openWsNoFirst(ws('/live'));
    await until('upstream', () => c.open.size === 1);
    a.ws.send('1000');
    b.ws.send('200');
    a.ws.send('G28 ; home everything');
    b.ws.send('ping');
    expect(await b.next()).toBe('pong');
    await until('rate sent upstream', () => c.received.includes('rate 200'));
    expect(c.received).not.toContain('G28 ; home everything');
    expect(c.received).not.toContain('ping');
    await b.close();
    await until('slower rate once the fast viewer left', () => c.received.at(-1) === 'rate 1000');
  });

  it('a throttled browser gets state at its own rate, the newest each time, and events at once', async () => {
    const c = await startController();
    const { ws } = await gateway(c, [fanout()]);
    const slowRate = await openWsNoFirst(ws('/live'));
    slowRate.ws.send('400');
    await until('upstream', () => c.received.includes('rate 400'));
    c.broadcast('state:a');
    expect(await slowRate.next()).toBe('state:a');
    c.broadcast('state:b');
    c.broadcast('state:c');
    await sleep(100);
    expect(slowRate.take()).toBeUndefined(); // throttled
    c.broadcast('event 1');
    // The event goes at once, with the newest waiting state before it (it came first).
    expect(await slowRate.next()).toBe('state:c');
    expect(await slowRate.next()).toBe('event 1');
  });

  it('redacts the machine secrets in shared frames', async () => {
    const c = await startController();
    const { ws } = await gateway(c, [fanout()], { apiKey: 'sekret-api-key-123' });
    const a = await openWsNoFirst(ws('/live'));
    await until('upstream', () => c.open.size === 1);
    c.broadcast('log the key is sekret-api-key-123');
    const f = await a.next();
    expect(f).not.toContain('sekret-api-key-123');
    expect(f).toContain('[redacted]');
  });

  it('when the controller closes, every viewer is closed and the next one opens a fresh socket', async () => {
    const c = await startController();
    const { ws } = await gateway(c, [fanout()]);
    const a = await openWsNoFirst(ws('/live'));
    const b = await openWsNoFirst(ws('/live'));
    await until('upstream', () => c.open.size === 1);
    const closes = Promise.all(
      [a, b].map((x) => new Promise<number>((r) => x.ws.once('close', (code) => r(code)))),
    );
    for (const s of c.open) s.close(1000, 'restarting');
    expect(await closes).toEqual([1011, 1011]);
    await openWsNoFirst(ws('/live'));
    await until('fresh upstream', () => c.opened === 2 && c.open.size === 1);
  });
});

describe('the stream a browser names (issue 31, finding 12)', () => {
  it('only declared query parameters, with declared values, choose the stream and reach the controller', async () => {
    const c = await startController();
    const { ws } = await gateway(c, [fanout({ query: { mode: ['fast', 'slow'] } })]);
    const a = await openWsNoFirst(ws('/live?mode=fast&x=1'));
    const b = await openWsNoFirst(ws('/live?cache=2&mode=fast'));
    const d = await openWsNoFirst(ws('/live?mode=slow'));
    await expect(openWsNoFirst(ws('/live?mode=other'))).rejects.toThrow('HTTP 400');
    await expect(openWsNoFirst(ws('/live?mode=fast&mode=slow'))).rejects.toThrow('HTTP 400');
    await until('two upstreams', () => c.open.size === 2);
    expect([...c.urls].sort()).toEqual(['/live?mode=fast', '/live?mode=slow']);
    void [a, b, d];
  });

  it('streamQuery drops what is not declared', () => {
    expect(streamQuery(fanout(), 'a=1&b=2')).toBe('');
    expect(streamQuery(fanout({ query: { m: ['x'] } }), 'z=1&m=x')).toBe('m=x');
    expect(streamQuery(fanout({ query: { m: ['x'] } }), 'm=y')).toBeInstanceOf(Error);
  });
});

describe('a burst of controller frames (issue 31, finding 13)', () => {
  it('20,000 state frames in one go: 64 handled at once, the rest coalesced into the newest, handled next turn', async () => {
    let deliver: (data: Buffer, isBinary: boolean) => void = () => undefined;
    const up: UpstreamSocket = {
      send: () => undefined,
      close: () => undefined,
      onMessage: (cb) => (deliver = cb),
      onClose: () => undefined,
    };
    const hub = new StreamHub(fanout(), up);
    cleanups.push(() => hub.close(1000, 'done'));
    const seen: string[] = [];
    hub.onFrame((f) => seen.push(f));
    for (let i = 0; i < 20_000; i++) deliver(Buffer.from(`state:${i}`), false);
    const batch = DEFAULT_STREAM_LIMITS.batchFrames;
    expect(seen).toHaveLength(batch);
    await new Promise((r) => setImmediate(r));
    expect(seen).toHaveLength(batch + 1);
    expect(seen.at(-1)).toBe('state:19999');
    expect(hub.stats.coalesced).toBe(20_000 - batch - 1);
  });

  it('events are never coalesced: they come in order, a turn at a time', async () => {
    let deliver: (data: Buffer, isBinary: boolean) => void = () => undefined;
    const up: UpstreamSocket = {
      send: () => undefined,
      close: () => undefined,
      onMessage: (cb) => (deliver = cb),
      onClose: () => undefined,
    };
    const hub = new StreamHub(fanout(), up);
    cleanups.push(() => hub.close(1000, 'done'));
    const seen: string[] = [];
    hub.onFrame((f) => seen.push(f));
    for (let i = 0; i < 150; i++) deliver(Buffer.from(i % 3 ? `log ${i}` : `state:${i}`), false);
    expect(seen.length).toBe(DEFAULT_STREAM_LIMITS.batchFrames);
    await until('every frame', () => seen.length === 150);
    expect(seen).toEqual(Array.from({ length: 150 }, (_, i) => (i % 3 ? `log ${i}` : `state:${i}`)));
  });
});

describe('simulated machines', () => {
  it('share one simulator socket among viewers, as hardware would', async () => {
    const t = tempDir();
    cleanups.push(t.cleanup);
    const gw = await startGateway({
      machines: {
        file: null,
        machines: [
          { id: 's1', name: 's1', kind: 'prunt', simulated: true, url: null, wsUrl: null, secrets: {} },
        ],
      },
      families: {
        prunt: family([fanout({ classify: () => ({ kind: 'latest', key: 'hello', replay: true }) })]),
      },
      dataDir: t.dir,
      env: {},
    });
    cleanups.push(gw.close);
    const url = `${gw.url.replace(/^http/, 'ws')}/machines/s1/live`;
    const a = await openWsNoFirst(url);
    const b = await openWsNoFirst(url);
    // The test simulator numbers its sockets in its greeting: both viewers got the first one's.
    expect(await a.next()).toBe('sim-hello 1');
    expect(await b.next()).toBe('sim-hello 1');
  });
});

describe('model streams (Duet DSF)', () => {
  it('a patch reaches three browsers that joined at different times, each with the full model first', async () => {
    const c = await startController(() => JSON.stringify({ state: { status: 'idle' }, job: { file: null } }));
    const { ws } = await gateway(c, [model]);
    const a = await openWsNoFirst(ws('/machine'));
    expect(JSON.parse(await a.next())).toEqual({ state: { status: 'idle' }, job: { file: null } });
    await until('the gateway acknowledged the full model', () => c.received.length === 1);
    expect(c.received).toEqual(['OK\n']);
    a.ws.send('OK\n');
    c.broadcast(JSON.stringify({ state: { status: 'processing' } }));
    expect(JSON.parse(await a.next())).toEqual({ state: { status: 'processing' } });

    const b = await openWsNoFirst(ws('/machine'));
    expect(JSON.parse(await b.next())).toEqual({ state: { status: 'processing' }, job: { file: null } });
    a.ws.send('OK\n');
    b.ws.send('OK\n');
    c.broadcast(JSON.stringify({ job: { file: 'part.gcode' } }));
    expect(JSON.parse(await a.next())).toEqual({ job: { file: 'part.gcode' } });
    expect(JSON.parse(await b.next())).toEqual({ job: { file: 'part.gcode' } });

    const late = await openWsNoFirst(ws('/machine'));
    expect(JSON.parse(await late.next())).toEqual({
      state: { status: 'processing' },
      job: { file: 'part.gcode' },
    });
    late.ws.send('OK\n');
    a.ws.send('OK\n');
    b.ws.send('OK\n');
    c.broadcast(JSON.stringify({ state: { status: 'paused' } }));
    for (const x of [a, b, late]) expect(JSON.parse(await x.next())).toEqual({ state: { status: 'paused' } });
    expect(c.opened).toBe(1);
  });

  it('a browser that has not acknowledged gets one patch covering what it missed, events included', async () => {
    const c = await startController(() => JSON.stringify({ state: { status: 'idle' }, heat: { t: 20 } }));
    const { ws } = await gateway(c, [model]);
    const a = await openWsNoFirst(ws('/machine'));
    await a.next();
    await until('acknowledged', () => c.received.length === 1);
    c.broadcast(JSON.stringify({ heat: { t: 30 } }));
    c.broadcast(JSON.stringify({ heat: { t: 40 }, messages: [{ type: 0, content: 'hello' }] }));
    c.broadcast(JSON.stringify({ state: { status: 'busy' } }));
    await until('the gateway acknowledged every patch', () => c.received.length === 4);
    await sleep(50);
    expect(a.take()).toBeUndefined(); // no OK from this browser yet: nothing sent
    a.ws.send('OK\n');
    expect(JSON.parse(await a.next())).toEqual({
      heat: { t: 40 },
      state: { status: 'busy' },
      messages: [{ type: 0, content: 'hello' }],
    });
  });

  it('pings a quiet controller itself: a slow one that answers stays, a silent one is dropped within 2.25 periods (issue 15)', async () => {
    const c = await startController(() => JSON.stringify({ state: { status: 'idle' } }));
    const everyMs = 1000;
    const pinged: ModelStreamDecl = {
      ...model,
      ping: { frame: 'PING\n', everyMs, isPong: (f) => f.trim() === 'PONG' },
    };
    const { ws } = await gateway(c, [pinged]);
    const a = await openWsNoFirst(ws('/machine'));
    await a.next();
    await until('upstream', () => c.open.size === 1);
    const [up] = [...c.open];
    if (!up) throw new Error('no upstream');
    // An idle controller on a slow link: each keep-alive is answered a little more than a
    // period later (the round trip of a link with latency). It is kept: only silence counts.
    let answering = true;
    let lastSent = Date.now();
    up.on('message', (d) => {
      if (String(d).trim() !== 'PING') return;
      setTimeout(() => {
        if (!answering || up.readyState !== WebSocket.OPEN) return;
        lastSent = Date.now();
        up.send('PONG\n');
      }, everyMs * 1.05);
    });
    await sleep(everyMs * 4.5);
    expect(c.open.size).toBe(1);
    expect(c.opened).toBe(1);
    expect(a.ws.readyState).toBe(WebSocket.OPEN);
    const pings = c.received.filter((f) => f === 'PING\n').length;
    expect(pings).toBeGreaterThanOrEqual(2);
    expect(pings).toBeLessThanOrEqual(4); // about once a period of silence, never a storm
    expect(a.take()).toBeUndefined(); // the controller's PONGs are the gateway's, not the browser's
    // It falls silent: every viewer is closed (1011) 2.25 periods after its last frame.
    const closed = new Promise<{ code: number; reason: string; at: number }>((r) =>
      a.ws.once('close', (code, reason) => r({ code, reason: String(reason), at: Date.now() })),
    );
    answering = false;
    const got = await closed;
    expect(got.code).toBe(1011);
    expect(got.reason).toMatch(/stopped answering/);
    expect(got.at - lastSent).toBeGreaterThanOrEqual(everyMs * 2.25 - 20);
    expect(got.at - lastSent).toBeLessThan(everyMs * 2.25 + 250);
    await until('the upstream socket closed', () => c.open.size === 0);
  }, 15_000);

  it('a patch that does not apply closes every viewer with 1007 (bad data); the next one starts afresh', async () => {
    const c = await startController(() => JSON.stringify({ state: { status: 'idle' } }));
    const { ws } = await gateway(c, [model]);
    const a = await openWsNoFirst(ws('/machine'));
    await a.next();
    await until('upstream', () => c.open.size === 1);
    const closed = new Promise<{ code: number; reason: string }>((r) =>
      a.ws.once('close', (code, reason) => r({ code, reason: String(reason) })),
    );
    c.broadcast('{"state": not json');
    expect(await closed).toEqual({ code: 1007, reason: 'the controller sent a patch that does not apply' });
    await until('the upstream socket closed', () => c.open.size === 0);
    const b = await openWsNoFirst(ws('/machine'));
    expect(JSON.parse(await b.next())).toEqual({ state: { status: 'idle' } });
    expect(c.opened).toBe(2);
  });

  it('answers the browser keep-alive itself and never forwards browser frames', async () => {
    const c = await startController(() => JSON.stringify({ state: {} }));
    const { ws } = await gateway(c, [model]);
    const a = await openWsNoFirst(ws('/machine'));
    await a.next();
    a.ws.send('PING\n');
    expect(await a.next()).toBe('PONG\n');
    a.ws.send('M112');
    await sleep(100);
    expect(c.received).toEqual(['OK\n']);
  });
});

/** A browser socket that collects frames (none expected at open). */
async function openWsNoFirst(url: string): Promise<{
  ws: WebSocket;
  next(): Promise<string>;
  take(): string | undefined;
  close(): Promise<void>;
}> {
  const origin = new URL(url.replace(/^ws/, 'http')).origin;
  const ws = new WebSocket(url, { headers: { Origin: origin } });
  const queue: string[] = [];
  const waiters: Array<(s: string) => void> = [];
  ws.on('message', (d) => {
    const s = String(d);
    const w = waiters.shift();
    if (w) w(s);
    else queue.push(s);
  });
  await new Promise<void>((resolve, reject) => {
    ws.once('open', () => resolve());
    ws.once('error', reject);
    ws.once('unexpected-response', (_q, res) => reject(new Error(`HTTP ${res.statusCode ?? 0}`)));
  });
  cleanups.push(() => ws.terminate());
  return {
    ws,
    next: () =>
      new Promise((r, reject) => {
        const q = queue.shift();
        if (q !== undefined) return r(q);
        const t = setTimeout(() => reject(new Error('no frame within 3 s')), 3000);
        waiters.push((s) => {
          clearTimeout(t);
          r(s);
        });
      }),
    take: () => queue.shift(),
    close: () =>
      new Promise<void>((r) => {
        if (ws.readyState === WebSocket.CLOSED) r();
        else {
          ws.once('close', () => r());
          ws.close();
        }
      }),
  };
}
