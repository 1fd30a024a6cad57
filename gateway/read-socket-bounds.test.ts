import { afterEach, describe, expect, it } from 'vitest';
import { WebSocket } from 'ws';
import { xtoolFamily } from '../src/controllers/xtool/family';
import type { FamilyDescriptor, SharingHints } from '../src/fleet/contract';
import { READ_SOCKET_LIMITS } from './read-socket';
import {
  consoleFetch,
  gatewayFor,
  login,
  openWs,
  stubEntry,
  stubFor,
  testFamily,
  user,
  type Running,
  type Stub,
} from './test-util';

/**
 * What one signed-in viewer can make the gateway do to everybody else through the read socket
 * (read-socket.ts) and a machine's read slots (upstream-http.ts): jam a machine's reads with URLs
 * `http.request` cannot send, or make the server hold answers a page never reads. Real sockets,
 * the real gateway, a stub controller; every wait is bounded (no wall-clock race decides a result).
 */

const cleanups: Array<() => Promise<void> | void> = [];
afterEach(async () => {
  for (const c of cleanups.splice(0).reverse()) await c();
});

const sleep = (ms: number): Promise<void> => new Promise((r) => setTimeout(r, ms));

async function until(what: string, ok: () => boolean, ms = 8000): Promise<void> {
  const end = Date.now() + ms;
  while (!ok()) {
    if (Date.now() > end) throw new Error(`timed out waiting for ${what}`);
    await sleep(10);
  }
}

/** Resolves with `p`, or rejects after `ms`: a jammed read fails the test instead of hanging it. */
async function within<T>(what: string, p: Promise<T>, ms = 5000): Promise<T> {
  let timer: ReturnType<typeof setTimeout> | undefined;
  const late = new Promise<never>((_r, reject) => {
    timer = setTimeout(() => reject(new Error(`${what}: no answer within ${ms} ms`)), ms);
  });
  try {
    return await Promise.race([p, late]);
  } finally {
    clearTimeout(timer);
  }
}

interface Reader {
  ws: WebSocket;
  send(msg: unknown): void;
  next(): Promise<Record<string, unknown>>;
  closed: Promise<number>;
}

async function reader(gw: Running, cookie: string): Promise<Reader> {
  const w = await openWs(`ws://${gw.host}/api/reads`, { Cookie: cookie }, false);
  cleanups.push(() => w.ws.terminate());
  const closed = new Promise<number>((r) => w.ws.once('close', (code) => r(code)));
  return {
    ws: w.ws,
    closed,
    send: (msg) => w.ws.send(typeof msg === 'string' ? msg : JSON.stringify(msg)),
    next: async () => JSON.parse(await within('a socket answer', w.next())) as Record<string, unknown>,
  };
}

// ---------------------------------------------------------------- finding 1: jammed read slots

describe('a viewer cannot jam a machine’s reads with URLs that cannot be sent', () => {
  it(
    'raw spaces and characters above U+00FF over the read socket: 400 each; everyone’s reads and the watch’s go on',
    { timeout: 40_000 },
    async () => {
      const stub = await stubFor(cleanups);
      const sharing = xtoolFamily.gateway?.sharing;
      const watch = sharing?.watch;
      if (!sharing || !watch) throw new Error('the xTool family declares no watch');
      expect(sharing.maxConcurrentReads).toBe(2);
      const family: FamilyDescriptor = {
        ...xtoolFamily,
        gateway: { ...xtoolFamily.gateway, sharing: { ...sharing, watch: { ...watch, everyMs: 100 } } },
      };
      const gw = await gatewayFor(cleanups, [stubEntry('acc-laser', stub.url, { kind: 'xtool' })], {
        families: { xtool: family },
        users: [user('vera', 'viewer', 'viewer-pass-1'), user('otto', 'operator', 'operator-pass-1')],
        watch: true,
        // A jammed slot answers 503 after this wait (the gateway's timeout otherwise: 15 s).
        upstream: { queueTimeoutMs: 1500 },
      });
      const vera = await login(gw.url, 'vera', 'viewer-pass-1');
      const otto = await login(gw.url, 'otto', 'operator-pass-1');
      const r = await reader(gw, vera);
      const bad = [
        '/machines/acc-laser/ping?x= y',
        '/machines/acc-laser/ping?x=\u0100',
        '/machines/acc-laser/ping?x=\u00e9',
      ];
      let id = 0;
      for (let round = 0; round < 3; round++)
        for (const url of bad) {
          r.send({ id: ++id, url });
          const a = await r.next();
          expect(a.status).toBe(400);
          expect(String(a.body)).toMatch(/percent-encode/);
        }
      expect(stub.seen.some((s) => s.url.startsWith('/ping'))).toBe(false);
      // Another user's reads, over HTTP and over a socket, several at once: answered, none refused.
      const polls = (): number =>
        stub.seen.filter((s) => s.url.startsWith('/system?action=get_working_sta')).length;
      const pollsBefore = polls();
      const answers = await within(
        'other users’ reads',
        Promise.all(
          Array.from({ length: 6 }, () =>
            consoleFetch(`${gw.url}/machines/acc-laser/ping`, { headers: { Cookie: otto } }).then(
              (x) => x.status,
            ),
          ),
        ),
      );
      expect(answers).toEqual([200, 200, 200, 200, 200, 200]);
      const o = await reader(gw, otto);
      o.send({ id: 1, url: '/machines/acc-laser/ping' });
      expect((await o.next()).status).toBe(200);
      // The watch's own reads still reach the laser.
      // (A jammed slot answers the watch 503 from the queue: that poll would never reach the laser.)
      await until('the watch polls the laser again', () => polls() >= pollsBefore + 2, 15_000);
      const stats = gw.gw.upstreamStats('acc-laser');
      expect(stats?.refusedReads).toBe(0);
      await until('no read slot held', () => gw.gw.upstreamStats('acc-laser')?.readsInFlight === 0);
    },
  );
});

describe('the same on a simulated machine (answered inside the gateway)', () => {
  it('malformed read URLs are 400 and never reach the simulator; its one read slot stays free', async () => {
    const base = testFamily('prunt');
    const seen: string[] = [];
    const family: FamilyDescriptor = {
      ...base,
      gateway: {
        ...base.gateway,
        sharing: { shareRead: () => null, keepAlive: false, maxConcurrentReads: 1 },
      },
      createSimulator: (o) => {
        const sim = base.createSimulator(o);
        return { ...sim, fetch: (req, p) => (seen.push(p), sim.fetch(req, p)) };
      },
    };
    const gw = await gatewayFor(cleanups, [stubEntry('s1', null, { simulated: true })], {
      families: { prunt: family },
      users: [user('vera', 'viewer', 'viewer-pass-1')],
      upstream: { queueTimeoutMs: 2000 },
    });
    const cookie = await login(gw.url, 'vera', 'viewer-pass-1');
    const r = await reader(gw, cookie);
    let id = 0;
    for (const url of ['/machines/s1/status?x= y', '/machines/s1/status?x=\u0100', '/machines/s1/st atus'])
      for (let i = 0; i < 2; i++) {
        r.send({ id: ++id, url });
        expect((await r.next()).status).toBe(400);
      }
    expect(seen).toEqual([]);
    r.send({ id: ++id, url: '/machines/s1/status' });
    expect((await r.next()).status).toBe(200);
    const h = await within(
      'HTTP read',
      consoleFetch(`${gw.url}/machines/s1/status`, { headers: { Cookie: cookie } }),
    );
    expect(h.status).toBe(200);
    expect(gw.gw.upstreamStats('s1')?.refusedReads).toBe(0);
    // The simulator was reached by the well-formed reads only.
    expect(seen).toEqual(['/status', '/status']);
  });
});

// ---------------------------------------------------------------- finding 1: every way a read ends

/** One read slot, no queue wait beyond 2 s: a slot not given back makes the next read a 503. */
const oneSlot: SharingHints = { shareRead: () => null, keepAlive: false, maxConcurrentReads: 1 };

async function slotRig(opts: { timeoutMs?: number; sharing?: SharingHints } = {}): Promise<{
  gw: Running;
  stub: Stub;
  cookie: string;
  /** A read over HTTP: its status (a jammed slot: 503 after the queue's 2 s). */
  read(): Promise<number>;
}> {
  const stub = await stubFor(cleanups);
  const base = testFamily('prunt');
  const family: FamilyDescriptor = {
    ...base,
    gateway: {
      ...base.gateway,
      sharing: opts.sharing ?? oneSlot,
      // `/throw`: a header Node refuses to write, so `http.request` throws as it is created.
      injectSecrets(req) {
        if (req.path === '/throw') req.headers['X-Bad'] = 'a\nb';
      },
    },
  };
  const gw = await gatewayFor(cleanups, [stubEntry('p1', stub.url)], {
    families: { prunt: family },
    users: [user('vera', 'viewer', 'viewer-pass-1'), user('sara', 'supervisor', 'supervisor-pass-1')],
    upstream: { queueTimeoutMs: 2000 },
    ...(opts.timeoutMs ? { timeoutMs: opts.timeoutMs } : {}),
  });
  const cookie = await login(gw.url, 'vera', 'viewer-pass-1');
  stub.respond = (req, res) => {
    if (req.url === '/hang') return; // never answers
    if (req.url === '/reset') {
      req.socket.destroy();
      return;
    }
    res.writeHead(200, { 'Content-Type': 'application/json' });
    res.end('{"ok":true}');
  };
  const read = async (): Promise<number> =>
    (await within('a read', consoleFetch(`${gw.url}/machines/p1/status`, { headers: { Cookie: cookie } })))
      .status;
  return { gw, stub, cookie, read };
}

describe('a read slot is given back on every way a read ends', () => {
  for (const shared of [false, true]) {
    const sharing: SharingHints = shared ? { ...oneSlot, shareRead: () => 0 } : oneSlot;
    const kind = shared ? 'shared read' : 'read';

    it(`${kind}: the request throws as it is created (socket and HTTP)`, async () => {
      const g = await slotRig({ sharing });
      const r = await reader(g.gw, g.cookie);
      for (let id = 1; id <= 3; id++) {
        r.send({ id, url: '/machines/p1/throw' });
        const a = await r.next();
        expect(a.status).toBeGreaterThanOrEqual(500);
        expect(String(a.body)).not.toMatch(/a\nb/);
      }
      for (let i = 0; i < 3; i++) {
        const h = await within(
          'HTTP read',
          consoleFetch(`${g.gw.url}/machines/p1/throw`, { headers: { Cookie: g.cookie } }),
        );
        expect(h.status).toBeGreaterThanOrEqual(500);
      }
      expect(await g.read()).toBe(200);
      expect(g.gw.gw.upstreamStats('p1')?.refusedReads).toBe(0);
    });

    it(`${kind}: a command that throws as it is created is answered and audited, never left hanging`, async () => {
      const g = await slotRig({ sharing });
      const sara = await login(g.gw.url, 'sara', 'supervisor-pass-1');
      const h = await within(
        'a command',
        consoleFetch(`${g.gw.url}/machines/p1/throw`, {
          method: 'POST',
          headers: { Cookie: sara },
          body: 'x',
        }),
      );
      expect(h.status).toBe(502);
      expect(await h.text()).not.toMatch(/a\nb/);
      await g.gw.gw.audit.flush();
      const line = g.gw.gw.audit.all().find((e) => e.type === 'command' && e.path === '/throw');
      expect(line?.result).toBe('error');
      expect(String(line?.error)).toMatch(/not sent/);
      expect(g.stub.seen.length).toBe(0);
      expect(await g.read()).toBe(200);
    });

    it(`${kind}: the controller's connection breaks (socket error)`, async () => {
      const g = await slotRig({ sharing });
      const r = await reader(g.gw, g.cookie);
      for (let id = 1; id <= 3; id++) {
        r.send({ id, url: '/machines/p1/reset' });
        expect((await r.next()).status).toBe(502);
      }
      expect(await g.read()).toBe(200);
      expect(g.gw.gw.upstreamStats('p1')?.refusedReads).toBe(0);
    });

    it(`${kind}: the page cancels it, or closes its socket, while the controller has not answered`, async () => {
      const g = await slotRig({ sharing });
      const r = await reader(g.gw, g.cookie);
      r.send({ id: 1, url: '/machines/p1/hang' });
      await until('the controller got the read', () => g.stub.seen.some((s) => s.url === '/hang'));
      r.send({ cancel: 1 });
      await until(
        'the slot is free after the cancel',
        () => g.gw.gw.upstreamStats('p1')?.readsInFlight === 0,
      );
      expect(await g.read()).toBe(200);
      const r2 = await reader(g.gw, g.cookie);
      r2.send({ id: 1, url: '/machines/p1/hang' });
      await until(
        'the controller got it again',
        () => g.stub.seen.filter((s) => s.url === '/hang').length === 2,
      );
      r2.ws.close();
      await until('the slot is free after the close', () => g.gw.gw.upstreamStats('p1')?.readsInFlight === 0);
      expect(await g.read()).toBe(200);
      expect(g.gw.gw.upstreamStats('p1')?.refusedReads).toBe(0);
    });

    it(`${kind}: a read waiting for the slot is dropped when its page closes the socket`, async () => {
      const g = await slotRig({ sharing });
      const r = await reader(g.gw, g.cookie);
      r.send({ id: 1, url: '/machines/p1/hang' });
      r.send({ id: 2, url: '/machines/p1/hang?second=1' });
      await until('one read upstream, one waiting', () => g.gw.gw.upstreamStats('p1')?.queueLength === 1);
      r.ws.close();
      await until('nothing held', () => {
        const st = g.gw.gw.upstreamStats('p1');
        return st?.readsInFlight === 0 && st.queueLength === 0;
      });
      expect(g.stub.seen.filter((s) => s.url.startsWith('/hang')).length).toBe(1);
      expect(await g.read()).toBe(200);
    });

    it(`${kind}: the controller does not answer within the gateway's timeout`, async () => {
      const g = await slotRig({ sharing, timeoutMs: 300 });
      const r = await reader(g.gw, g.cookie);
      r.send({ id: 1, url: '/machines/p1/hang' });
      expect((await r.next()).status).toBe(504);
      expect(await g.read()).toBe(200);
      expect(g.gw.gw.upstreamStats('p1')?.refusedReads).toBe(0);
    });
  }
});

// ---------------------------------------------------------------- finding 6: held bytes

describe('one viewer cannot make the server hold their unread answers', () => {
  const MiB = 1024 * 1024;
  /** The most the gateway may hold for one user (gathered and unsent), as documented. */
  const bound = READ_SOCKET_LIMITS.maxHeldPerUser;

  async function rig(
    size: number,
  ): Promise<{ gw: Running & { usersFile: string }; stub: Stub; cookie: string }> {
    const stub = await stubFor(cleanups);
    const job = Buffer.alloc(size, 0x41);
    stub.respond = (req, res) => {
      res.writeHead(200, { 'Content-Type': 'text/plain' });
      res.end(req.url?.startsWith('/file') ? job : 'ok');
    };
    const gw = await gatewayFor(cleanups, [stubEntry('p1', stub.url)], {
      users: [user('vera', 'viewer', 'viewer-pass-1')],
    });
    const cookie = await login(gw.url, 'vera', 'viewer-pass-1');
    return { gw, stub, cookie };
  }

  /** `n` sockets that never read what they are sent (their TCP side paused). */
  async function deaf(gw: Running, cookie: string, n: number): Promise<Reader[]> {
    const out: Reader[] = [];
    for (let i = 0; i < n; i++) {
      const r = await reader(gw, cookie);
      r.ws.pause();
      out.push(r);
    }
    return out;
  }

  it('sockets per user are bounded: one more is refused (429)', async () => {
    const { gw, cookie } = await rig(1);
    await deaf(gw, cookie, READ_SOCKET_LIMITS.maxSocketsPerUser);
    await expect(openWs(`ws://${gw.host}/api/reads`, { Cookie: cookie }, false)).rejects.toMatchObject({
      status: 429,
    });
    expect(gw.gw.readSockets()).toBe(READ_SOCKET_LIMITS.maxSocketsPerUser);
  });

  it(
    'eight deaf sockets × three reads of an 8 MB job file: told to read over HTTP, nothing large held',
    { timeout: 40_000 },
    async () => {
      const { gw, stub, cookie } = await rig(8 * MiB);
      const rssBefore = process.memoryUsage().rss;
      let rssPeak = rssBefore;
      const sampler = setInterval(() => (rssPeak = Math.max(rssPeak, process.memoryUsage().rss)), 5);
      cleanups.push(() => clearInterval(sampler));
      const sockets = await deaf(gw, cookie, 8);
      let id = 0;
      for (const r of sockets)
        for (let i = 0; i < 3; i++) r.send({ id: ++id, url: `/machines/p1/file?n=${id}` });
      await until('the controller was asked 24 times', () => stub.seen.length >= 24, 15_000);
      await until('nothing gathered any more', () => gw.gw.readSocketHeld().gathering === 0, 15_000);
      clearInterval(sampler);
      // Before the bound: about 1 GB held (117 → 1,113 MB). A generous margin for the test's own buffers.
      expect(rssPeak - rssBefore).toBeLessThan(200 * MiB);
      const held = gw.gw.readSocketHeld();
      expect(held.peak).toBeLessThanOrEqual(bound);
      // A reading socket of the same user is told to read such an answer over HTTP.
      for (const r of sockets) r.ws.terminate();
      await until('the deaf sockets are gone', () => gw.gw.readSockets() === 0);
      const r = await reader(gw, cookie);
      r.send({ id: 1, url: '/machines/p1/file' });
      const a = await r.next();
      expect(String(a.fallback)).toMatch(/over HTTP/);
    },
  );

  it(
    'answers under the size limit, many per deaf socket: held bytes stay under the per-user bound',
    { timeout: 40_000 },
    async () => {
      const { gw, stub, cookie } = await rig(900 * 1024);
      const sockets = await deaf(gw, cookie, READ_SOCKET_LIMITS.maxSocketsPerUser);
      let id = 0;
      const perSocket = 20;
      for (const r of sockets)
        for (let i = 0; i < perSocket; i++) r.send({ id: ++id, url: `/machines/p1/file?n=${id}` });
      const total = sockets.length * perSocket;
      await until('the controller was asked for every read', () => stub.seen.length >= total, 20_000);
      await until('nothing gathered any more', () => gw.gw.readSocketHeld().gathering === 0, 20_000);
      const held = gw.gw.readSocketHeld();
      // Without the bound: 160 answers of 900 kB, 140 MB queued for pages that never read.
      expect(total * 900 * 1024).toBeGreaterThan(10 * bound);
      expect(held.peak).toBeLessThanOrEqual(bound);
      expect(held.unsent).toBeLessThanOrEqual(bound);
      expect(held.peak).toBeGreaterThan(0);
    },
  );
});
