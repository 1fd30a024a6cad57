import { afterEach, describe, expect, it } from 'vitest';
import { ROLES } from '../../src/fleet/types';
import { READ_METHODS } from '../proxy-http';
import { SIM_API_PATH } from '../sim-api';
import {
  consoleFetch,
  gatewayFor,
  hashFast,
  login,
  stubEntry,
  stubFor,
  testFamily,
  user,
  type Cleanups,
  type Running,
} from '../test-util';
import { routeKey, type ApiRoute, type GuardedRoute } from './route';

/**
 * The `/api/*` route table (api.ts, routes/) against the real gateway on a real socket: every
 * route declares what it needs, no two share a method and path, what the table says agrees with
 * what the gateway enforces (the console header of csrf.ts; a viewer refused from every
 * supervisor's route, every refusal written to the audit log).
 */

const cleanups: Cleanups = [];
afterEach(async () => {
  for (const c of cleanups.splice(0).reverse()) await c();
});

const PW = { vera: 'viewer-pass-1', otto: 'operator-pass-1', sam: 'supervisor-pass-1' };

async function setup(): Promise<{ gw: Running; vera: string; sam: string }> {
  const stub = await stubFor(cleanups);
  const gw = await gatewayFor(
    cleanups,
    [stubEntry('p1', stub.url), stubEntry('demo', null, { simulated: true })],
    {
      users: [
        user('vera', 'viewer', PW.vera),
        user('otto', 'operator', PW.otto),
        user('sam', 'supervisor', PW.sam, { pinHash: hashFast('471147') }),
      ],
      // A family with routes of its own, one for supervisors (as xTool's discovery).
      families: {
        prunt: {
          ...testFamily('prunt'),
          server: {
            routes: [
              {
                name: 'probe',
                role: 'supervisor',
                forbidden: 'probing is for supervisors',
                handle: () => Promise.resolve({ status: 200, body: { probed: true } }),
              },
            ],
          },
        },
      },
    },
  );
  return { gw, vera: await login(gw.url, 'vera', PW.vera), sam: await login(gw.url, 'sam', PW.sam) };
}

/** A path the route answers. */
function pathOf(r: ApiRoute): string {
  if (typeof r.path === 'string') return r.path;
  expect(r.example, `${routeKey(r)} gives an example path`).toBeDefined();
  return r.example ?? '';
}

describe('the /api route table', () => {
  it('every route declares a role, whether it changes state and is audited; none shares a method and path', async () => {
    const { gw } = await setup();
    const routes = gw.gw.apiRoutes;
    // The gateway's own areas and the family's route are all in it.
    for (const p of ['/api/session', '/api/login', '/api/machines', '/api/audit', '/api/alarms/ack'])
      expect(routes.some((r) => r.path === p)).toBe(true);
    expect(routes.some((r) => r.path === '/api/settings' && r.method === 'PUT')).toBe(true);
    expect(routes.some((r) => r.path === '/api/probe/prunt')).toBe(true);
    const keys = new Set<string>();
    for (const r of routes) {
      expect(['public', ...ROLES], routeKey(r)).toContain(r.role);
      expect(typeof r.changesState, routeKey(r)).toBe('boolean');
      expect(typeof r.audited, routeKey(r)).toBe('boolean');
      // What csrf.ts enforces (gateway.ts: every method but GET/HEAD/OPTIONS needs the header).
      expect(r.changesState, routeKey(r)).toBe(!READ_METHODS.has(r.method));
      if (r.bodyLimit !== undefined) expect(r.bodyLimit, routeKey(r)).toBeGreaterThan(0);
      if (r.role !== 'public' && r.auditRefusal) expect(r.audited, routeKey(r)).toBe(true);
      if (typeof r.path !== 'string') expect(r.path.test(pathOf(r)), routeKey(r)).toBe(true);
      expect(keys.has(routeKey(r)), `${routeKey(r)} declared twice`).toBe(false);
      keys.add(routeKey(r));
    }
  });

  it('every state-changing route is refused without the console header, before it runs', async () => {
    const { gw, sam } = await setup();
    const changing = gw.gw.apiRoutes.filter((r) => r.changesState);
    expect(changing.length).toBeGreaterThan(5);
    for (const r of changing) {
      const before = gw.gw.audit.all().length;
      // A supervisor's session: only the missing header can refuse it.
      const res = await fetch(`${gw.url}${pathOf(r)}`, {
        method: r.method,
        headers: { Cookie: sam, 'Content-Type': 'application/json' },
        body: r.method === 'GET' ? undefined : '{}',
      });
      expect(res.status, routeKey(r)).toBe(403);
      expect(await res.json(), routeKey(r)).toMatchObject({ crossSite: true });
      const added = gw.gw.audit.all().slice(before);
      expect(added, routeKey(r)).toMatchObject([
        { type: 'refused', user: 'sam', method: r.method, error: expect.stringContaining('X-Shopdeck') },
      ]);
    }
    // The session was not ended by a forged logout, nor the settings changed.
    const session = (await (
      await consoleFetch(`${gw.url}/api/session`, { headers: { Cookie: sam } })
    ).json()) as {
      user: { name: string } | null;
    };
    expect(session.user?.name).toBe('sam');
  });

  it("a viewer's request to every supervisor route is refused 403 and written to the audit log", async () => {
    const { gw, vera } = await setup();
    const supervisors = gw.gw.apiRoutes.filter((r): r is GuardedRoute => r.role === 'supervisor');
    // The audit, settings, TLS, simulator and the family's routes.
    expect(supervisors.length).toBeGreaterThanOrEqual(9);
    // A change to a simulator names its machine in the refusal; every other one its path.
    expect(supervisors.filter((r) => r.auditRefusal).map(routeKey)).toEqual([`POST ${String(SIM_API_PATH)}`]);
    for (const r of supervisors) {
      const before = gw.gw.audit.all().length;
      const res = await consoleFetch(`${gw.url}${pathOf(r)}`, {
        method: r.method,
        headers: { Cookie: vera, 'Content-Type': 'application/json' },
        body: r.method === 'GET' ? undefined : '{}',
      });
      expect(res.status, routeKey(r)).toBe(403);
      const body = (await res.json()) as { error: string; needs: string };
      expect(body.needs, routeKey(r)).toBe('supervisor');
      expect(body.error, routeKey(r)).toMatch(/supervisor/);
      const added = gw.gw.audit.all().slice(before);
      expect(added, routeKey(r)).toMatchObject([
        {
          type: 'refused',
          result: 'refused',
          user: 'vera',
          method: r.method,
          role: 'supervisor',
          error: body.error,
          path: r.auditRefusal ? expect.any(String) : pathOf(r).split('?')[0],
        },
      ]);
    }
  });
});
