import http, { type IncomingHttpHeaders, type IncomingMessage, type ServerResponse } from 'node:http';
import type { AddressInfo } from 'node:net';
import { afterEach, describe, expect, it } from 'vitest';
import type { FamilyDescriptor, HeldSessionHooks, SharingHints } from '../src/fleet/contract';
import type { MachineEntry } from './machines';
import { consoleFetch, startGateway, tempDir, testFamily, type Running } from './test-util';
import type { UpstreamLimits, UpstreamStats } from './upstream-http';

/**
 * One upstream per machine, HTTP side (upstream-http.ts). Real sockets: the real gateway on a
 * plain server, and a controller stand-in that counts requests and TCP connections and holds its
 * answers until a test lets them go. The families are the tests' own (not src/controllers).
 */

const cleanups: Array<() => Promise<void> | void> = [];
afterEach(async () => {
  for (const c of cleanups.splice(0).reverse()) await c();
});

const SECRET = 'K3y-of-the-C0ntroller-9183';

interface Seen {
  method: string;
  url: string;
  headers: IncomingHttpHeaders;
  body: string;
}

interface Ctl {
  url: string;
  seen: Seen[];
  /** TCP connections the controller accepted. */
  connections: number;
  /** Requests whose connection the gateway closed before the answer was written. */
  aborted: string[];
  respond: (req: IncomingMessage, res: ServerResponse, body: string) => void | Promise<void>;
  close(): Promise<void>;
}

/** Each request's number, in the order the controller got them. */
const numberOf = new WeakMap<IncomingMessage, number>();

/** The default answer: JSON with the path, the request's number, the API key it got, a cookie. */
function answer(req: IncomingMessage, res: ServerResponse): void {
  res.writeHead(200, {
    'Content-Type': 'application/json',
    'Set-Cookie': 'ctrl=abc; Path=/',
    'X-Ctrl': 'yes',
  });
  res.end(JSON.stringify({ path: req.url, n: numberOf.get(req), key: req.headers['x-api-key'] ?? null }));
}

async function controller(): Promise<Ctl> {
  const ctl = { seen: [], connections: 0, aborted: [] } as unknown as Ctl;
  ctl.respond = (req, res) => answer(req, res);
  const server = http.createServer((req, res) => {
    const chunks: Buffer[] = [];
    req.on('data', (c: Buffer) => chunks.push(c));
    req.on('end', () => {
      const body = Buffer.concat(chunks).toString('utf8');
      ctl.seen.push({ method: req.method ?? '', url: req.url ?? '', headers: req.headers, body });
      numberOf.set(req, ctl.seen.length);
      res.on('close', () => {
        if (!res.writableFinished) ctl.aborted.push(req.url ?? '');
      });
      void ctl.respond(req, res, body);
    });
  });
  server.on('connection', () => ctl.connections++);
  await new Promise<void>((r) => server.listen(0, '127.0.0.1', () => r()));
  ctl.url = `http://127.0.0.1:${(server.address() as AddressInfo).port}`;
  ctl.close = async () => {
    server.closeAllConnections();
    await new Promise<void>((r) => server.close(() => r()));
  };
  cleanups.push(ctl.close);
  return ctl;
}

/** Answers wait until `open()`. */
function gate(): { wait: Promise<void>; open(): void } {
  let open = (): void => undefined;
  const wait = new Promise<void>((r) => {
    open = r;
  });
  return { wait, open: () => open() };
}

const sleep = (ms: number): Promise<void> => new Promise((r) => setTimeout(r, ms));

async function waitFor(what: string, cond: () => boolean, ms = 3000): Promise<void> {
  const until = Date.now() + ms;
  while (!cond()) {
    if (Date.now() > until) throw new Error(`timed out waiting for ${what}`);
    await sleep(5);
  }
}

function entry(id: string, url: string | null, extra: Partial<MachineEntry> = {}): MachineEntry {
  return {
    id,
    name: id,
    kind: 'prunt',
    simulated: false,
    url: url ? new URL(url) : null,
    wsUrl: null,
    secrets: {},
    ...extra,
  };
}

function family(sharing: SharingHints | undefined, session?: HeldSessionHooks): FamilyDescriptor {
  const base = testFamily('prunt');
  return { ...base, gateway: { ...base.gateway, sharing, session } };
}

const shareAll = (windowMs: number, more: Partial<SharingHints> = {}): SharingHints => ({
  shareRead: () => windowMs,
  keepAlive: false,
  maxConcurrentReads: 8,
  ...more,
});

interface Gw extends Running {
  stats(): UpstreamStats;
  get(path: string, init?: RequestInit): Promise<Got>;
}

interface Got {
  status: number;
  body: string;
  headers: Headers;
}

async function setup(
  machine: MachineEntry,
  fam: FamilyDescriptor,
  extra: { timeoutMs?: number; upstream?: Partial<UpstreamLimits>; now?: () => number } = {},
): Promise<Gw> {
  const t = tempDir();
  cleanups.push(t.cleanup);
  const running = await startGateway({
    machines: { file: null, machines: [machine] },
    families: { prunt: fam },
    dataDir: t.dir,
    env: {},
    timeoutMs: extra.timeoutMs,
    upstream: extra.upstream,
    now: extra.now,
  });
  cleanups.push(running.close);
  const stats = (): UpstreamStats => {
    const s = running.gw.upstreamStats(machine.id);
    if (!s) throw new Error('no stats');
    return s;
  };
  const get = async (p: string, init: RequestInit = {}): Promise<Got> => {
    const r = await consoleFetch(`${running.url}/machines/${machine.id}${p}`, {
      signal: AbortSignal.timeout(5000),
      ...init,
    });
    return { status: r.status, body: await r.text(), headers: r.headers };
  };
  return { ...running, stats, get };
}

describe('shared reads', () => {
  it("gives two browsers' identical reads one upstream request, redacted, without Set-Cookie, and again within the window", async () => {
    const ctl = await controller();
    const g = gate();
    ctl.respond = async (req, res) => {
      await g.wait;
      answer(req, res);
    };
    const gw = await setup(entry('p1', ctl.url, { secrets: { apiKey: SECRET } }), family(shareAll(2000)));
    const a = gw.get('/status?x=1');
    await waitFor('the first read upstream', () => ctl.seen.length === 1);
    const b = gw.get('/status?x=1');
    await waitFor('the second browser to join', () => gw.stats().waitingBrowsers === 2);
    g.open();
    const [ra, rb] = await Promise.all([a, b]);
    // Within the window, after the answer: the same answer again.
    const rc = await gw.get('/status?x=1');
    expect(ctl.seen).toHaveLength(1);
    expect(ctl.seen[0]?.headers['x-api-key']).toBe(SECRET);
    for (const r of [ra, rb, rc]) {
      expect(r.status).toBe(200);
      expect(r.body).toBe(ra.body);
      expect(r.body).toContain('[redacted]');
      expect(r.body).not.toContain(SECRET);
      expect(r.headers.get('set-cookie')).toBeNull();
      expect(r.headers.get('x-ctrl')).toBe('yes');
      expect(r.headers.get('content-security-policy')).toMatch(/sandbox/);
    }
    expect(gw.stats()).toMatchObject({ upstreamRequests: 1, sharedAnswers: 2 });
  });

  it('sends a read again once its window is over (injected clock)', async () => {
    const ctl = await controller();
    let t = 1_000_000;
    const gw = await setup(entry('p1', ctl.url), family(shareAll(100)), { now: () => t });
    const first = await gw.get('/status');
    t += 99;
    expect((await gw.get('/status')).body).toBe(first.body);
    expect(ctl.seen).toHaveLength(1);
    t += 2;
    const later = await gw.get('/status');
    expect(ctl.seen).toHaveLength(2);
    expect(later.body).not.toBe(first.body);
  });

  it('never merges reads the controller could answer differently; per-browser headers do not split them', async () => {
    const ctl = await controller();
    const g = gate();
    ctl.respond = async (req, res) => {
      await g.wait;
      answer(req, res);
    };
    const gw = await setup(entry('p1', ctl.url), family(shareAll(2000)));
    const reads = [
      gw.get('/status?a=1'),
      gw.get('/status?a=2'),
      gw.get('/other?a=1'),
      gw.get('/status?a=1', { headers: { Accept: 'text/plain' } }),
      gw.get('/status?a=1', { headers: { Range: 'bytes=0-3' } }),
      gw.get('/status?a=1', { headers: { Authorization: 'Bearer other-user' } }),
    ];
    await waitFor('six upstream reads', () => ctl.seen.length === 6);
    // Another browser: another user agent and cache headers, the same read otherwise.
    const same = gw.get('/status?a=1', {
      headers: { 'User-Agent': 'Tablet at the machine', 'Cache-Control': 'no-cache', 'If-None-Match': '"x"' },
    });
    await waitFor('the seventh browser to join', () => gw.stats().waitingBrowsers === 7);
    g.open();
    const got = await Promise.all([...reads, same]);
    expect(ctl.seen).toHaveLength(6);
    expect(new Set(got.slice(0, 6).map((r) => r.body)).size).toBe(6);
    expect(got[6]?.body).toBe(got[0]?.body);
    // The first browser's own headers did not go upstream either: the shared read is nobody's.
    expect(ctl.seen[0]?.headers['user-agent']).toBeUndefined();
    expect(ctl.seen[0]?.headers['if-none-match']).toBeUndefined();
    expect(ctl.seen[3]?.headers.accept).toBe('text/plain');
    expect(ctl.seen[4]?.headers.range).toBe('bytes=0-3');
  });

  it('gives a failed upstream read to the browsers that joined it, and never keeps it', async () => {
    const ctl = await controller();
    const g = gate();
    let fail = true;
    ctl.respond = async (req, res) => {
      await g.wait;
      if (fail) req.socket.destroy();
      else answer(req, res);
    };
    const gw = await setup(entry('p1', ctl.url), family(shareAll(5000)));
    const a = gw.get('/status');
    await waitFor('the read upstream', () => ctl.seen.length === 1);
    const b = gw.get('/status');
    await waitFor('the second browser to join', () => gw.stats().waitingBrowsers === 2);
    g.open();
    for (const r of await Promise.all([a, b])) {
      expect(r.status).toBe(502);
      expect(JSON.parse(r.body)).toMatchObject({ gateway: true });
      expect(r.headers.get('x-shopdeck-gateway')).toBe('error');
    }
    fail = false;
    const c = await gw.get('/status');
    expect(c.status).toBe(200);
    expect(ctl.seen).toHaveLength(2);
  });

  it('does not keep a timed-out read, and cuts every joined answer when the controller cuts it', async () => {
    const ctl = await controller();
    let mode: 'silent' | 'cut' | 'ok' = 'silent';
    const g = gate();
    ctl.respond = async (req, res) => {
      if (mode === 'silent') return;
      if (mode === 'cut') {
        await g.wait;
        res.writeHead(200, { 'Content-Type': 'application/json', 'Content-Length': '100' });
        res.write('{"partial":');
        setTimeout(() => req.socket.destroy(), 20);
        return;
      }
      answer(req, res);
    };
    const gw = await setup(entry('p1', ctl.url), family(shareAll(5000)), { timeoutMs: 300 });
    const timedOut = await gw.get('/status');
    expect(timedOut.status).toBe(504);
    mode = 'cut';
    const a = gw.get('/status');
    await waitFor('the read upstream', () => ctl.seen.length === 2);
    const b = gw.get('/status');
    await waitFor('the second browser to join', () => gw.stats().waitingBrowsers === 2);
    g.open();
    const cut = await Promise.allSettled([a, b]);
    expect(cut.map((r) => r.status)).toEqual(['rejected', 'rejected']);
    mode = 'ok';
    expect((await gw.get('/status')).status).toBe(200);
    expect(ctl.seen).toHaveLength(3);
  });

  it('does not cancel a shared read when one browser leaves; it does when all have left', async () => {
    const ctl = await controller();
    const g = gate();
    ctl.respond = async (req, res) => {
      await g.wait;
      if (!res.destroyed) answer(req, res);
    };
    const gw = await setup(entry('p1', ctl.url), family(shareAll(2000)));
    const leaving = new AbortController();
    const a = gw.get('/status', { signal: leaving.signal });
    await waitFor('the read upstream', () => ctl.seen.length === 1);
    const b = gw.get('/status');
    await waitFor('the second browser to join', () => gw.stats().waitingBrowsers === 2);
    leaving.abort();
    await expect(a).rejects.toThrow();
    await waitFor('the first browser to be gone', () => gw.stats().waitingBrowsers === 1);
    await sleep(50);
    expect(ctl.aborted).toEqual([]);
    g.open();
    const rb = await b;
    expect(rb.status).toBe(200);
    expect(ctl.seen).toHaveLength(1);
    expect(ctl.aborted).toEqual([]);

    // Every browser gone: the upstream request is abandoned, as an unshared one would be.
    const g2 = gate();
    ctl.respond = async (req, res) => {
      await g2.wait;
      if (!res.destroyed) answer(req, res);
    };
    const c1 = new AbortController();
    const c2 = new AbortController();
    const c = gw.get('/status?other=1', { signal: c1.signal });
    await waitFor('the read upstream', () => ctl.seen.length === 2);
    const d = gw.get('/status?other=1', { signal: c2.signal });
    await waitFor('the second browser to join', () => gw.stats().waitingBrowsers === 2);
    c1.abort();
    c2.abort();
    await Promise.allSettled([c, d]);
    await waitFor('the controller to see the request abandoned', () => ctl.aborted.length === 1);
    g2.open();
  });

  it('streams an answer too large to keep to the browsers that joined it, and keeps nothing', async () => {
    const ctl = await controller();
    const g = gate();
    const big = 'x'.repeat(5000);
    ctl.respond = async (_req, res) => {
      await g.wait;
      res.writeHead(200, { 'Content-Type': 'text/plain' });
      res.end(big);
    };
    const gw = await setup(entry('p1', ctl.url), family(shareAll(5000)), {
      upstream: { maxSharedBytes: 1024 },
    });
    const a = gw.get('/big');
    await waitFor('the read upstream', () => ctl.seen.length === 1);
    const b = gw.get('/big');
    await waitFor('the second browser to join', () => gw.stats().waitingBrowsers === 2);
    g.open();
    for (const r of await Promise.all([a, b])) expect(r.body).toBe(big);
    expect(ctl.seen).toHaveLength(1);
    expect((await gw.get('/big')).body).toBe(big);
    expect(ctl.seen).toHaveLength(2);
  });

  it('keeps a bounded number of answers per machine', async () => {
    const ctl = await controller();
    const gw = await setup(entry('p1', ctl.url), family(shareAll(60_000)), {
      upstream: { maxCachedAnswers: 2 },
    });
    await gw.get('/status?q=1');
    await gw.get('/status?q=2');
    await gw.get('/status?q=3');
    expect(gw.stats().cachedAnswers).toBe(2);
    await gw.get('/status?q=3');
    expect(ctl.seen).toHaveLength(3);
    await gw.get('/status?q=1'); // the oldest was dropped
    expect(ctl.seen).toHaveLength(4);
  });

  it('shares nothing for a family that declares no sharing', async () => {
    const ctl = await controller();
    const g = gate();
    ctl.respond = async (req, res) => {
      await g.wait;
      answer(req, res);
    };
    const gw = await setup(entry('p1', ctl.url), family(undefined));
    const a = gw.get('/status');
    const b = gw.get('/status');
    await waitFor('both reads upstream', () => ctl.seen.length === 2);
    g.open();
    const [ra, rb] = await Promise.all([a, b]);
    expect(ra.body).not.toBe(rb.body);
    expect(gw.stats()).toMatchObject({ upstreamRequests: 2, sharedAnswers: 0 });
  });

  it('shares the reads of a simulated machine as well', async () => {
    const gw = await setup(entry('demo', null, { simulated: true }), family(shareAll(60_000)));
    const a = await gw.get('/status');
    const b = await gw.get('/status');
    expect(a.status).toBe(200);
    expect(b.body).toBe(a.body);
    expect(gw.stats()).toMatchObject({ upstreamRequests: 1, sharedAnswers: 1 });
    await gw.get('/job?action=pause', { headers: { 'X-Shopdeck-Command': 'test.pause' } });
    expect(gw.stats()).toMatchObject({ upstreamRequests: 2, commands: 1 });
  });
});

describe('commands', () => {
  it('sends every command of every browser, in order, never merged, even when identical', async () => {
    const ctl = await controller();
    const g = gate();
    ctl.respond = async (req, res, body) => {
      await g.wait;
      res.writeHead(200, { 'Content-Type': 'application/json' });
      res.end(JSON.stringify({ url: req.url, body }));
    };
    // Every path shareable: only being a command keeps these from being shared.
    const gw = await setup(entry('p1', ctl.url), family(shareAll(60_000)));
    const sent: Array<Promise<Got>> = [];
    const commands: Array<[string, RequestInit]> = [
      ['/settings', { method: 'POST', body: 'speed=1', headers: { 'X-Shopdeck-Command': 'c1' } }],
      ['/settings', { method: 'POST', body: 'speed=1', headers: { 'X-Shopdeck-Command': 'c2' } }],
      ['/job?action=pause', { headers: { 'X-Shopdeck-Command': 'c3' } }],
      ['/job?action=pause', { headers: { 'X-Shopdeck-Command': 'c4' } }],
    ];
    for (const [p, init] of commands) {
      sent.push(gw.get(p, init));
      await waitFor(`${p} upstream`, () => ctl.seen.length === sent.length);
    }
    g.open();
    for (const r of await Promise.all(sent)) expect(r.status).toBe(200);
    expect(ctl.seen.map((s) => `${s.method} ${s.url} ${s.body}`)).toEqual([
      'POST /settings speed=1',
      'POST /settings speed=1',
      'GET /job?action=pause ',
      'GET /job?action=pause ',
    ]);
    expect(gw.gw.audit.all().map((e) => e.clientCommand)).toEqual(['c1', 'c2', 'c3', 'c4']);
    expect(gw.stats()).toMatchObject({ upstreamRequests: 4, commands: 4, sharedAnswers: 0 });
    // Nor kept: the same command once more reaches the controller.
    await gw.get('/job?action=pause', { headers: { 'X-Shopdeck-Command': 'c5' } });
    expect(ctl.seen).toHaveLength(5);
  });

  it('does not serve a read kept from before a command after it', async () => {
    const ctl = await controller();
    const gw = await setup(entry('p1', ctl.url), family(shareAll(60_000)));
    const before = await gw.get('/status');
    expect((await gw.get('/status')).body).toBe(before.body);
    await gw.get('/settings', { method: 'POST', body: 'x=1' });
    const after = await gw.get('/status');
    expect(after.body).not.toBe(before.body);
    expect(ctl.seen.map((s) => `${s.method} ${s.url}`)).toEqual([
      'GET /status',
      'POST /settings',
      'GET /status',
    ]);
  });
});

describe('connections and limits', () => {
  for (const keepAlive of [true, false]) {
    it(`keepAlive ${keepAlive}: five reads one after another use ${keepAlive ? 'one TCP connection' : 'five'}`, async () => {
      const ctl = await controller();
      const gw = await setup(
        entry('p1', ctl.url),
        family({ shareRead: () => null, keepAlive, maxConcurrentReads: 2 }),
      );
      for (let i = 0; i < 5; i++) expect((await gw.get(`/status?i=${i}`)).status).toBe(200);
      expect(ctl.seen).toHaveLength(5);
      expect(ctl.connections).toBe(keepAlive ? 1 : 5);
    });
  }

  it('lets at most maxConcurrentReads reads upstream; a command passes the waiting reads at once', async () => {
    const ctl = await controller();
    const g = gate();
    ctl.respond = async (req, res) => {
      if (req.method === 'GET') await g.wait;
      answer(req, res);
    };
    const gw = await setup(
      entry('p1', ctl.url),
      family({ shareRead: () => null, keepAlive: true, maxConcurrentReads: 2 }),
    );
    const reads = [gw.get('/slow?n=1'), gw.get('/slow?n=2'), gw.get('/slow?n=3')];
    await waitFor(
      'two reads upstream, one waiting',
      () => ctl.seen.length === 2 && gw.stats().queueLength === 1,
    );
    await sleep(100);
    expect(ctl.seen).toHaveLength(2);
    const command = await gw.get('/settings', { method: 'POST', body: 'x=1' });
    expect(command.status).toBe(200);
    expect(ctl.seen.map((s) => s.method)).toEqual(['GET', 'GET', 'POST']);
    // A waiting read whose browser leaves never goes upstream.
    const leaving = new AbortController();
    const gone = gw.get('/slow?n=4', { signal: leaving.signal });
    await waitFor('a second read waiting', () => gw.stats().queueLength === 2);
    leaving.abort();
    await expect(gone).rejects.toThrow();
    await waitFor('the read to leave the queue', () => gw.stats().queueLength === 1);
    g.open();
    for (const r of await Promise.all(reads)) expect(r.status).toBe(200);
    expect(ctl.seen.map((s) => s.url)).toEqual(['/slow?n=1', '/slow?n=2', '/settings', '/slow?n=3']);
    expect(gw.stats()).toMatchObject({ queuedReads: 2, readsInFlight: 0, queueLength: 0 });
  });

  it('bounds the queue: 503 when it is full or a read waited too long; a read whose browser left is dropped', async () => {
    const ctl = await controller();
    const g = gate();
    ctl.respond = async (req, res) => {
      await g.wait;
      answer(req, res);
    };
    const gw = await setup(
      entry('p1', ctl.url),
      family({ shareRead: () => 1000, keepAlive: false, maxConcurrentReads: 1 }),
      { upstream: { maxQueuedReads: 1, queueTimeoutMs: 400 } },
    );
    const a = gw.get('/slow?n=1');
    await waitFor('the first read upstream', () => ctl.seen.length === 1);
    const b = gw.get('/slow?n=2');
    await waitFor('the second read queued', () => gw.stats().queueLength === 1);
    const full = await gw.get('/slow?n=3');
    expect(full.status).toBe(503);
    expect(JSON.parse(full.body)).toMatchObject({ gateway: true, error: expect.stringMatching(/busy/) });
    expect(full.headers.get('x-shopdeck-gateway')).toBe('error');
    const waited = await b;
    expect(waited.status).toBe(503);
    expect(JSON.parse(waited.body)).toMatchObject({
      gateway: true,
      error: expect.stringMatching(/waited 400 ms/),
    });
    // A queued read whose browser leaves is dropped from the queue.
    const leaving = new AbortController();
    const c = gw.get('/slow?n=4', { signal: leaving.signal });
    await waitFor('the read queued', () => gw.stats().queueLength === 1);
    leaving.abort();
    await expect(c).rejects.toThrow();
    await waitFor('the queue to be empty', () => gw.stats().queueLength === 0);
    g.open();
    expect((await a).status).toBe(200);
    expect((await gw.get('/slow?n=5')).status).toBe(200);
    expect(ctl.seen.map((s) => s.url)).toEqual(['/slow?n=1', '/slow?n=5']);
    expect(gw.stats()).toMatchObject({ refusedReads: 2, queuedReads: 2 });
  });
});

describe('held sessions', () => {
  /** A controller with session keys (`GET /connect` → key; `X-Key` on every other request, 403 when unknown). */
  async function keyed(): Promise<{
    ctl: Ctl;
    valid: Set<string>;
    connectFails: { now: boolean };
    g: { gate: ReturnType<typeof gate> | null };
  }> {
    const ctl = await controller();
    const valid = new Set<string>();
    const connectFails = { now: false };
    const g: { gate: ReturnType<typeof gate> | null } = { gate: null };
    let n = 0;
    ctl.respond = async (req, res) => {
      if (req.url === '/connect') {
        if (connectFails.now) {
          res.writeHead(500, { 'Content-Type': 'text/plain' });
          res.end('connect failed');
          return;
        }
        const key = `key-${++n}-abcdef`;
        valid.add(key);
        res.writeHead(200, { 'Content-Type': 'application/json' });
        res.end(JSON.stringify({ key }));
        return;
      }
      const wait = g.gate;
      g.gate = null;
      if (wait) await wait.wait;
      const key = req.headers['x-key'];
      if (typeof key !== 'string' || !valid.has(key)) {
        res.writeHead(403);
        res.end();
        return;
      }
      answer(req, res);
    };
    return { ctl, valid, connectFails, g };
  }

  const hooks: HeldSessionHooks = {
    intercept: () => null,
    async open(upstream) {
      const a = await upstream('GET', '/connect');
      if (a.status !== 200) return { ok: false, answer: a };
      return { ok: true, key: (JSON.parse(a.body) as { key: string }).key, answer: { ...a, body: '{}' } };
    },
    apply(req, key) {
      delete req.headers['x-key'];
      if (key) req.headers['x-key'] = key;
    },
    applyWs: () => undefined,
    isExpired: (status) => status === 403,
  };

  it('re-sends a shared read whose key expired once, for every browser that joined it', async () => {
    const { ctl, valid, connectFails, g } = await keyed();
    const gw = await setup(entry('p1', ctl.url), family(shareAll(60_000), hooks));
    expect((await gw.get('/status?a=1')).status).toBe(200);
    valid.clear(); // the controller forgot the session
    g.gate = gate();
    const opened = g.gate;
    const a = gw.get('/status?a=2');
    await waitFor('the read upstream', () => ctl.seen.length === 3);
    const b = gw.get('/status?a=2');
    await waitFor('the second browser to join', () => gw.stats().waitingBrowsers === 2);
    opened.open();
    const [ra, rb] = await Promise.all([a, b]);
    expect(ra.status).toBe(200);
    expect(rb.body).toBe(ra.body);
    expect(ctl.seen.map((s) => s.url)).toEqual([
      '/connect',
      '/status?a=1',
      '/status?a=2',
      '/connect',
      '/status?a=2',
    ]);

    // No new key to be had: every browser that joined gets the refusal (none is left waiting),
    // and it is not kept.
    valid.clear();
    connectFails.now = true;
    g.gate = gate();
    const refused = g.gate;
    const c = gw.get('/status?a=3');
    await waitFor('the read upstream', () => ctl.seen.length === 6);
    const d = gw.get('/status?a=3');
    await waitFor('the second browser to join', () => gw.stats().waitingBrowsers === 2);
    refused.open();
    const [rc, rd] = await Promise.all([c, d]);
    expect([rc.status, rd.status]).toEqual([500, 500]);
    connectFails.now = false;
    expect((await gw.get('/status?a=3')).status).toBe(200);
  });
});
