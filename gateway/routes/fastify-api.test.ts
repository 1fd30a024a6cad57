import http from 'node:http';
import { afterEach, describe, expect, it } from 'vitest';
import {
  consoleFetch,
  gatewayFor,
  login,
  stubEntry,
  stubFor,
  testFamily,
  user,
  type Cleanups,
  type Running,
} from '../test-util';
import { fastifyUrl, fixedPrefix, routingPath } from './fastify-api';
import { resolveRoute } from './route';

/**
 * `/api/*` on Fastify (fastify-api.ts) answers the paths the table answers, and only those:
 * odd paths (slashes, escapes, case, dot segments, long segments) against the table's own
 * matching (`resolveRoute`, the dispatcher's before Fastify), on the real gateway and socket.
 */

const cleanups: Cleanups = [];
afterEach(async () => {
  for (const c of cleanups.splice(0).reverse()) await c();
});

async function setup(): Promise<Running> {
  const stub = await stubFor(cleanups);
  return gatewayFor(cleanups, [stubEntry('p1', stub.url), stubEntry('demo', null, { simulated: true })], {
    users: [user('sam', 'supervisor', 'supervisor-pass-1')],
    families: {
      prunt: {
        ...testFamily('prunt'),
        server: {
          routes: [
            {
              name: 'probe',
              role: 'supervisor',
              forbidden: 'probing is for supervisors',
              handle: () => Promise.resolve({ status: 200, body: {} }),
            },
          ],
        },
      },
    },
  });
}

/** One request with `rawPath` sent as it is (no client normalises it); status, headers, body. */
function raw(
  gw: Running,
  method: string,
  rawPath: string,
  headers: Record<string, string> = {},
  body?: Buffer,
): Promise<{ status: number; headers: http.IncomingHttpHeaders; body: string }> {
  const { hostname, port } = new URL(gw.url);
  return new Promise((resolve, reject) => {
    const length = body ? { 'Content-Length': String(body.length) } : {};
    const req = http.request({
      host: hostname,
      port,
      method,
      path: rawPath,
      headers: { 'X-Shopdeck': '1', ...length, ...headers },
    });
    req.on('response', (res) => {
      const chunks: Buffer[] = [];
      res.on('data', (c: Buffer) => chunks.push(c));
      res.on('end', () =>
        resolve({
          status: res.statusCode ?? 0,
          headers: res.headers,
          body: Buffer.concat(chunks).toString(),
        }),
      );
    });
    req.on('error', reject);
    req.end(body);
  });
}

const LONG = 'x'.repeat(300);
const ODD_PATHS = [
  '/api',
  '/api/',
  '/api?x=1',
  '/api/session',
  '/api/session/',
  '/api//session',
  '/api/Session',
  '/api/SESSION',
  '/api/sess%69on',
  '/api/%73ession',
  '/api/session%2F',
  '/api/session%2f',
  '/api/./session',
  '/api/x/../session',
  '/api/%2E/session',
  '/api/session/.',
  '/api/session?x=1&y',
  '/api/session;x',
  '/api/session%3Bx',
  '/api\\session',
  '/api/session%00',
  '/api/session%20',
  '/api/%',
  '/api/%zz',
  '/api/%25',
  '/api/ma%63hines',
  '/api/machines',
  '/api/machines/',
  '/api/machines/demo/temperatures',
  '/api/machines/demo/temperatures/',
  '/api/machines//temperatures',
  '/api/machines/de%2Fmo/temperatures',
  '/api/machines/de/mo/temperatures',
  `/api/machines/${LONG}/temperatures`,
  '/api/machines/%/temperatures',
  '/api/sim/demo',
  '/api/sim/demo/',
  '/api/sim//demo',
  '/api/sim/',
  '/api/sim',
  '/api/sim/%64emo',
  '/api/sim/de%2Fmo',
  '/api/sim/%',
  `/api/sim/${LONG}`,
  '/api/SIM/demo',
  '/api/history/jobs',
  '/api/history/jobs.csv',
  '/api/history/jobs%2Ecsv',
  '/api/history/JOBS',
  '/api/history/',
  '/api/history/jobs/x',
  '/api/tls',
  '/api/tls/',
  '/api/tls/p1',
  '/api/tls/P1',
  '/api/tls/%70%31',
  `/api/tls/${LONG}`,
  '/api/audit',
  '/api/audit.csv',
  '/api/audit%2Ecsv',
  '/api/auditXcsv',
  '/api/alarms/ack',
  '/api/settings',
  '/api/settings/test-webhook',
  '/api/probe/prunt',
  '/api/probe/PRUNT',
  '/api/probe/prunt/',
  '/api/no-such-thing',
];
const METHODS = ['GET', 'HEAD', 'POST', 'PUT', 'DELETE', 'OPTIONS', 'PATCH'];

describe('/api on Fastify', () => {
  it('every odd path and method answers as the table says: its route, its 405 with Allow, or its 404', async () => {
    const gw = await setup();
    const routes = gw.gw.apiRoutes;
    let routed = 0;
    let notAllowed = 0;
    for (const path of ODD_PATHS)
      for (const method of METHODS) {
        const found = resolveRoute(routes, method, new URL(path, 'http://gateway.local').pathname);
        const what = `${method} ${path}`;
        // Nobody signed in: a route of a role answers 401, so the route (not the 404) answered.
        const withBody = ['POST', 'PUT', 'PATCH', 'DELETE'].includes(method);
        const a = await raw(
          gw,
          method,
          path,
          { 'Content-Type': 'application/json' },
          withBody ? Buffer.from('{}') : undefined,
        );
        if (!(path === '/api' || path.startsWith('/api/') || path.startsWith('/api?'))) {
          // Not an /api path to the gateway (gateway.ts): the server's next handler answers.
          expect(a.status, what).toBe(404);
          if (method !== 'HEAD') expect(a.body, what).toBe('not the gateway');
          continue;
        }
        const error =
          method === 'HEAD' || a.body === ''
            ? null
            : ((JSON.parse(a.body) as { error?: string }).error ?? null);
        if (found.kind === 'none') {
          expect(a.status, `${what} ${a.body}`).toBe(404);
          if (method !== 'HEAD')
            expect(error, what).toBe(`no such endpoint: ${method} ${new URL(path, 'http://x').pathname}`);
        } else if (found.kind === 'not-allowed') {
          notAllowed++;
          expect(a.status, what).toBe(405);
          expect(a.headers.allow, what).toBe(found.allow);
          if (method !== 'HEAD') expect(error, what).toBe(found.error);
        } else {
          routed++;
          if (found.route.role !== 'public') expect(a.status, what).toBe(401);
          expect([404, 405].includes(a.status) && error?.startsWith('no such endpoint'), what).toBeFalsy();
          expect(a.status, what).not.toBe(405);
        }
        // Fastify's own answers never leak out.
        expect(a.body, what).not.toMatch(/"statusCode"|FST_/);
        expect(a.headers['x-content-type-options'], what).toBe('nosniff');
        expect(a.headers['cache-control'], what).toBe('no-store');
      }
    // The list reaches routes and 405s, not only 404s.
    expect(routed).toBeGreaterThan(20);
    expect(notAllowed).toBeGreaterThan(10);
  });

  it('bodies are read as before: over the limit 413, not JSON 400, unread ones neither buffered nor waited for', async () => {
    const gw = await setup();
    const sam = await login(gw.url, 'sam', 'supervisor-pass-1');
    const json = { 'Content-Type': 'application/json', Cookie: sam };
    const big = await raw(gw, 'PUT', '/api/settings', json, Buffer.alloc(20_000, 'a'));
    expect(big.status).toBe(413);
    expect(JSON.parse(big.body)).toEqual({ error: 'request body larger than 16384 bytes' });
    expect(big.headers['x-shopdeck-gateway']).toBe('error');
    const bad = await raw(gw, 'PUT', '/api/settings', json, Buffer.from('{"alarmWebhook":'));
    expect(bad.status).toBe(400);
    expect(JSON.parse(bad.body)).toMatchObject({ error: expect.stringMatching(/JSON/) });
    // A content type Fastify would refuse (415) is no matter to a route that reads JSON.
    const odd = await raw(
      gw,
      'PUT',
      '/api/settings',
      { ...json, 'Content-Type': 'nonsense' },
      Buffer.from('{}'),
    );
    expect(odd.status).toBe(400);
    expect(JSON.parse(odd.body)).toMatchObject({ error: expect.stringMatching(/send \{"alarmWebhook"/) });
    // A route that reads no body answers at once, however large the body (no 413: not read).
    const unread = await raw(gw, 'POST', '/api/session/activity', json, Buffer.alloc(2_000_000, 'a'));
    expect(unread.status).toBe(200);
    // A refused request's body is not read either: 401 before any body, whatever its size.
    const refused = await raw(
      gw,
      'PUT',
      '/api/settings',
      { 'Content-Type': 'application/json' },
      Buffer.alloc(100_000),
    );
    expect(refused.status).toBe(401);
    // And the gateway still answers.
    expect((await consoleFetch(`${gw.url}/api/session`, { headers: { Cookie: sam } })).status).toBe(200);
  });

  it('a pattern path routes on its fixed prefix; one Fastify could not route the same is refused', () => {
    expect(fixedPrefix(/^\/api\/sim\/(?<id>[^/]+)$/)).toBe('/api/sim/');
    expect(fixedPrefix(/^\/api\/history\/[a-z-]+(\.csv)?$/)).toBe('/api/history/');
    expect(fixedPrefix(/^\/api\/a\.b\/x$/)).toBe('/api/a.b/');
    // A prefix the pattern does not always have, or none at all.
    expect(fixedPrefix(/^\/api\/a\/?x$/)).toBe('/api/');
    expect(fixedPrefix(/^\/api\/sim\/x$/i)).toBeNull();
    expect(fixedPrefix(/^\/api\/a|^\/api\/b\//)).toBeNull();
    expect(fixedPrefix(/\/api\/sim\//)).toBeNull();
    expect(fixedPrefix(/^\/api.x\//)).toBeNull();
    const route = {
      method: 'GET',
      role: 'public',
      changesState: false,
      audited: false,
      handle: () => undefined,
    } as const;
    expect(fastifyUrl({ ...route, path: /^\/api\/sim\/(?<id>[^/]+)$/ })).toBe('/api/sim/*');
    expect(() => fastifyUrl({ ...route, path: '/api/:id' })).toThrow();
    expect(routingPath('/api/a%2Fb')).toBe('/api/a%252Fb');
  });
});
