import http, { type ServerResponse } from 'node:http';
import type { AddressInfo } from 'node:net';
import { afterEach, describe, expect, it } from 'vitest';
import { forceNoStore, safeAnswerHeaders } from './answer-headers';
import {
  consoleFetch,
  gatewayFor,
  login,
  stubEntry,
  stubFor,
  testFamily,
  testSimulator,
  user,
  type Cleanups,
} from './test-util';

/**
 * Finding 5: machine data stayed in a tablet's browser cache after logout. Controller caching
 * headers passed through, the gateway added no `no-store`, and logout cleared nothing: after a
 * supervisor signed out, the same URL was answered from the cache. Each test asks the real
 * gateway on real sockets and fails if an answer may be kept again.
 */

const cleanups: Cleanups = [];
afterEach(async () => {
  for (const c of cleanups.splice(0).reverse()) await c();
});

/** What a controller says to make the browser keep its answer. */
const CACHING = {
  'Cache-Control': 'public, max-age=86400, immutable',
  Expires: 'Thu, 01 Jan 2099 00:00:00 GMT',
  ETag: '"machine-data-1"',
  'Last-Modified': 'Mon, 01 Jan 2024 00:00:00 GMT',
  Age: '5',
  Pragma: 'cache',
};

/** Headers that let a browser (or a proxy) keep or revalidate an answer: none may be left. */
function expectNotKept(r: Response, what: string): void {
  expect(r.headers.get('cache-control'), what).toBe('no-store');
  for (const h of ['expires', 'etag', 'last-modified', 'age', 'pragma'])
    expect(r.headers.get(h), `${what}: ${h}`).toBeNull();
}

/** A family whose simulator answers with the controller's caching headers. */
function cachingFamily() {
  const f = testFamily('prunt');
  return {
    ...f,
    createSimulator: (o: { id: string }) => {
      const sim = testSimulator(o.id);
      return {
        ...sim,
        fetch: () =>
          Promise.resolve(
            new Response(JSON.stringify({ sim: o.id, position: [1, 2, 3] }), {
              status: 200,
              headers: { 'Content-Type': 'application/json', ...CACHING },
            }),
          ),
      };
    },
  };
}

async function fleet() {
  const s = await stubFor(cleanups);
  s.respond = (req, res) => {
    if (req.url === '/moved') {
      res.writeHead(302, { Location: '/status', ...CACHING });
      res.end();
      return;
    }
    if (req.url === '/missing') {
      res.writeHead(404, { 'Content-Type': 'text/plain', ...CACHING });
      res.end('no such thing');
      return;
    }
    if (req.headers['if-none-match']) {
      res.writeHead(304, CACHING);
      res.end();
      return;
    }
    res.writeHead(200, { 'Content-Type': 'application/json', ...CACHING });
    res.end(JSON.stringify({ position: [10, 20, 30], path: req.url }));
  };
  const g = await gatewayFor(
    cleanups,
    [
      stubEntry('plasma-1', s.url),
      stubEntry('sim-1', null, { simulated: true }),
      stubEntry('down', 'http://127.0.0.1:1'),
    ],
    {
      users: [user('sue', 'supervisor', 'sue-password-1'), user('vic', 'viewer', 'vic-password-1')],
      families: { prunt: cachingFamily() },
    },
  );
  return { s, g };
}

describe('5: no machine data may be kept by the browser', () => {
  it('a controller’s caching headers are replaced by no-store on every proxied answer', async () => {
    const { g } = await fleet();
    const cookie = await login(g.url, 'sue', 'sue-password-1');
    const get = (p: string, headers: Record<string, string> = {}) =>
      consoleFetch(`${g.url}/machines/${p}`, { headers: { Cookie: cookie, ...headers }, redirect: 'manual' });

    const ok = await get('plasma-1/status');
    expect(ok.status).toBe(200);
    expect(await ok.json()).toMatchObject({ position: [10, 20, 30] });
    expectNotKept(ok, 'controller answer');

    const head = await consoleFetch(`${g.url}/machines/plasma-1/status`, {
      method: 'HEAD',
      headers: { Cookie: cookie },
    });
    expectNotKept(head, 'HEAD');

    // A revalidation the browser would only make with a kept copy: the controller's 304 must not
    // bless one either.
    const revalidated = await get('plasma-1/status', { 'If-None-Match': '"machine-data-1"' });
    expectNotKept(revalidated, `revalidation (${revalidated.status})`);

    const moved = await get('plasma-1/moved');
    expect(moved.status).toBe(302);
    expectNotKept(moved, 'redirect');

    const missing = await get('plasma-1/missing');
    expect(missing.status).toBe(404);
    expectNotKept(missing, 'controller 404');

    const sim = await get('sim-1/status');
    expect(sim.status).toBe(200);
    expect(await sim.json()).toMatchObject({ sim: 'sim-1' });
    expectNotKept(sim, 'simulator answer');

    const down = await get('down/status');
    expect(down.status).toBeGreaterThanOrEqual(500);
    expectNotKept(down, 'gateway failure');

    const noMachine = await get('nope/status');
    expect(noMachine.status).toBe(404);
    expectNotKept(noMachine, 'unknown machine');
  });

  it('refusals are not kept either (a viewer’s refused command, a request without a session, a cross-site one)', async () => {
    const { g } = await fleet();
    const viewer = await login(g.url, 'vic', 'vic-password-1');
    const refused = await consoleFetch(`${g.url}/machines/plasma-1/job?action=stop`, {
      headers: { Cookie: viewer },
    });
    expect(refused.status).toBe(403);
    expectNotKept(refused, 'role refusal');
    const anonymous = await consoleFetch(`${g.url}/machines/plasma-1/status`);
    expect(anonymous.status).toBe(401);
    expectNotKept(anonymous, 'no session');
    const crossSite = await fetch(`${g.url}/machines/plasma-1/job?action=stop`, {
      headers: { Cookie: viewer, 'Sec-Fetch-Site': 'cross-site' },
    });
    expect(crossSite.status).toBe(403);
    expectNotKept(crossSite, 'cross-site refusal');
  });

  it('every /api answer is no-store', async () => {
    const { g } = await fleet();
    const cookie = await login(g.url, 'sue', 'sue-password-1');
    const api = (p: string, init: RequestInit = {}) =>
      consoleFetch(`${g.url}/api/${p}`, {
        ...init,
        headers: { Cookie: cookie, ...(init.headers as object) },
      });
    for (const p of ['session', 'machines', 'audit?limit=5', 'audit.csv', 'alarms', 'nope']) {
      const r = await api(p);
      await r.arrayBuffer();
      expectNotKept(r, `/api/${p} (${r.status})`);
    }
    const bad = await api('login', {
      method: 'POST',
      body: '{',
      headers: { 'Content-Type': 'application/json' },
    });
    expectNotKept(bad, `bad login (${bad.status})`);
  });

  it('logout tells the browser to clear its cache and storage; the session is gone', async () => {
    const { g } = await fleet();
    const cookie = await login(g.url, 'sue', 'sue-password-1');
    const out = await consoleFetch(`${g.url}/api/logout`, { method: 'POST', headers: { Cookie: cookie } });
    expect(out.status).toBe(200);
    expect(out.headers.get('clear-site-data')).toBe('"cache", "storage"');
    expectNotKept(out, 'logout');
    // The same URL after logout is refused by the gateway (nothing kept could answer it).
    const after = await consoleFetch(`${g.url}/machines/plasma-1/status`, { headers: { Cookie: cookie } });
    expect(after.status).toBe(401);
    expectNotKept(after, 'after logout');
    // Without a session too: a tablet whose session already lapsed still gets its cache cleared.
    const lapsed = await consoleFetch(`${g.url}/api/logout`, { method: 'POST' });
    expect(lapsed.headers.get('clear-site-data')).toBe('"cache", "storage"');
  });
});

describe('safeAnswerHeaders and caching', () => {
  it('drops every caching and validator header and says no-store', () => {
    const out = safeAnswerHeaders(
      {
        'content-type': 'application/json',
        'cache-control': 'public, max-age=60',
        expires: 'never',
        etag: 'W/"1"',
        'last-modified': 'yesterday',
        age: '1',
        pragma: 'cache',
        'surrogate-control': 'max-age=60',
        'x-accel-expires': '60',
      },
      { image: false },
    );
    expect(out['cache-control']).toBe('no-store');
    for (const h of [
      'expires',
      'etag',
      'last-modified',
      'age',
      'pragma',
      'surrogate-control',
      'x-accel-expires',
    ])
      expect(out[h], h).toBeUndefined();
    expect(out['content-type']).toBe('application/json');
  });
});

describe('forceNoStore', () => {
  it('holds every way of writing an answer’s head to no-store (real sockets)', async () => {
    const ways: Record<string, (res: ServerResponse) => void> = {
      object: (res) => {
        res.writeHead(200, { 'Content-Type': 'text/plain', ...CACHING });
        res.end('x');
      },
      reason: (res) => {
        res.writeHead(200, 'OK', CACHING);
        res.end('x');
      },
      flat: (res) => {
        res.writeHead(200, ['Cache-Control', 'max-age=60', 'ETag', '"1"', 'X-Kept', 'yes']);
        res.end('x');
      },
      setHeader: (res) => {
        for (const [k, v] of Object.entries(CACHING)) res.setHeader(k, v);
        res.end('x');
      },
      mixed: (res) => {
        res.setHeader('Expires', CACHING.Expires);
        res.writeHead(404, { 'cache-control': 'public, max-age=5', Age: '1' });
        res.end('x');
      },
    };
    const server = http.createServer((req, res) => {
      forceNoStore(res);
      ways[(req.url ?? '/').slice(1)]?.(res);
    });
    await new Promise<void>((r) => server.listen(0, '127.0.0.1', () => r()));
    cleanups.push(() => new Promise<void>((r) => server.close(() => r())));
    const base = `http://127.0.0.1:${(server.address() as AddressInfo).port}`;
    for (const way of Object.keys(ways)) {
      const r = await fetch(`${base}/${way}`);
      expect(await r.text()).toBe('x');
      expectNotKept(r, way);
      if (way === 'flat') expect(r.headers.get('x-kept')).toBe('yes');
    }
  });
});
