import path from 'node:path';
import { afterEach, beforeAll, describe, expect, it } from 'vitest';
import type { FamilyDescriptor } from '../src/fleet/contract';
import { MACHINE_KINDS } from '../src/controllers';
import { ROLES, roleAtLeast, type MachineKind, type Role } from '../src/fleet/types';
import type { Families } from './gateway';
import type { MachineEntry } from './machines';
import { login, openWs, startGateway, startStub, tempDir, user, writeJson, consoleFetch } from './test-util';

/**
 * Every role against every registered family's declared requests, HTTP and WebSocket: the
 * gateway allows exactly what the family's own access declaration allows for the role, and
 * nothing refused reaches the controller. Uses whatever src/controllers/families.ts registers.
 */

let families: Families = {};
let loadError: string | null = null;

beforeAll(async () => {
  try {
    families = (await import('../src/controllers/families')).families;
  } catch (e) {
    loadError = e instanceof Error ? e.message : String(e);
  }
});

const cleanups: Array<() => Promise<void> | void> = [];
afterEach(async () => {
  for (const c of cleanups.splice(0).reverse()) await c();
});

interface Probe {
  method: string;
  path: string;
  body?: string;
  ws?: boolean;
}

/** Requests everyone may try on any family: the family's declaration decides what they need. */
const GENERIC: Probe[] = [
  { method: 'GET', path: '/' },
  { method: 'GET', path: '/status' },
  { method: 'POST', path: '/', body: '{}' },
  { method: 'PUT', path: '/anything', body: '{}' },
  { method: 'DELETE', path: '/anything' },
  { method: 'GET', path: '/', ws: true },
];

/** Requests from the protocol documents, used only when that family is registered. */
const DOCUMENTED: Partial<Record<MachineKind, Probe[]>> = {
  xtool: [
    { method: 'GET', path: '/progress' },
    { method: 'GET', path: '/cnc/data?action=pause' },
    { method: 'GET', path: '/cnc/data?action=stop' },
    { method: 'GET', path: '/system?action=setFlameAlarmMode&mode=1' },
    { method: 'GET', path: '/system?action=version' },
  ],
  duet: [
    { method: 'GET', path: '/machine/status' },
    { method: 'POST', path: '/machine/code', body: 'M25' },
    { method: 'POST', path: '/machine/code', body: 'M112' },
    { method: 'POST', path: '/machine/code', body: 'G28' },
    { method: 'PUT', path: '/machine/file/0%3A%2Fgcodes%2Fpart.gcode', body: 'G1 X1' },
    { method: 'DELETE', path: '/machine/file/0%3A%2Fsys%2Fconfig.g' },
    { method: 'GET', path: '/machine', ws: true },
  ],
  touchcut: [
    { method: 'GET', path: '/rest/v1/status?units=metric' },
    { method: 'POST', path: '/rest/v1/auth/change-password', body: '{}' },
    { method: 'POST', path: '/rest/v1/settings', body: '{}' },
  ],
  prunt: [
    { method: 'GET', path: '/config/values' },
    { method: 'POST', path: '/pause/pause' },
    { method: 'POST', path: '/config/values', body: '{}' },
    { method: 'GET', path: '/websocket', ws: true },
  ],
  g2core: [
    { method: 'GET', path: '/machine/clear' },
    { method: 'PUT', path: '/machine/mfo', body: '{"mfo":1.2}' },
    { method: 'PUT', path: '/machine/xvm', body: '{"xvm":1000}' },
    { method: 'POST', path: '/operation', body: '{"lines":["G28.2 X0"]}' },
    { method: 'POST', path: '/operation', body: '{"lines":["M3 S1000"]}' },
  ],
};

const PW = 'family-test-pass';
const NAMES: Record<Role, string> = { viewer: 'vic', operator: 'ola', supervisor: 'sue' };

function declared(fam: FamilyDescriptor, p: Probe): Role {
  const [pathname, q = ''] = p.path.split('?') as [string, string?];
  return fam.access({
    method: p.method,
    path: pathname,
    query: new URLSearchParams(q),
    body: fam.accessNeedsBody?.(p.method, pathname) ? p.body : undefined,
    websocket: p.ws,
  }).role;
}

/**
 * Requests that reached the controller from a browser: not the gateway's own session requests
 * (a family whose session the gateway holds: the connect or login it intercepts, its
 * keep-alive). An "exchange" (TouchCut's password change) is the browser's request, sent by the
 * gateway with its key: it counts.
 */
function forwarded(fam: FamilyDescriptor, seen: ReadonlyArray<{ method: string; url: string }>): number {
  const held = fam.gateway?.session;
  if (!held) return seen.length;
  return seen.filter((s) => {
    const [p = '', q = ''] = s.url.split('?');
    const i = held.intercept({ method: s.method, path: p, query: new URLSearchParams(q) });
    const own = (i !== null && i.kind !== 'exchange') || (s.method === 'GET' && p === held.keepAlive?.path);
    return !own;
  }).length;
}

describe('registered families × roles', () => {
  it('loads the family registry', () => {
    expect(loadError).toBeNull();
    expect(Object.keys(families).length).toBeGreaterThan(0);
  });

  for (const kind of MACHINE_KINDS) {
    it(`${kind}: each role is allowed exactly the declared requests (HTTP and WebSocket)`, async (ctx) => {
      const fam = families[kind];
      if (!fam) {
        ctx.skip();
        return;
      }
      const probes = [...GENERIC, ...(DOCUMENTED[kind] ?? [])];
      const needs = probes.map((p) => declared(fam, p));
      // The test can only fail if the probes need different roles.
      expect(new Set(needs).size).toBeGreaterThan(1);

      const t = tempDir();
      cleanups.push(t.cleanup);
      // A DSF socket starts with the full model (the gateway's shared /machine stream reads it).
      const stub = await startStub(
        undefined,
        kind === 'duet' ? { greeting: '{"state":{"status":"idle"}}' } : {},
      );
      cleanups.push(stub.close);
      const usersFile = writeJson(path.join(t.dir, 'users.json'), {
        users: ROLES.map((r) => user(NAMES[r], r, PW)),
      });
      const m: MachineEntry = {
        id: `m-${kind}`,
        name: kind,
        kind,
        simulated: false,
        url: new URL(stub.url),
        wsUrl: new URL(stub.wsUrl),
        secrets: { apiKey: 'family-test-api-key', password: 'family-test-password' },
      };
      const gw = await startGateway({
        machines: { file: null, machines: [m] },
        families,
        dataDir: t.dir,
        usersFile,
        env: {},
      });
      cleanups.push(gw.close);

      for (const role of ROLES) {
        const cookie = await login(gw.url, NAMES[role], PW);
        for (const [i, p] of probes.entries()) {
          const need = needs[i]!;
          const allowed = roleAtLeast(role, need);
          const label = `${role} ${p.ws ? 'WS' : p.method} ${p.path} ${p.body ?? ''} (needs ${need})`;
          const before = forwarded(fam, stub.seen) + stub.wsSeen.length;
          const sharedBefore = gw.gw.upstreamStats(m.id)?.sharedAnswers ?? 0;
          const joinsBefore = gw.gw.streamStats(m.id).joined;
          const wsBefore = stub.wsSeen.length;
          let status: number;
          let body = '';
          if (p.ws) {
            try {
              const w = await openWs(`ws://${gw.host}/machines/${m.id}${p.path}`, { Cookie: cookie }, false);
              await w.close();
              status = 101;
            } catch (e) {
              status = (e as { status?: number }).status ?? 0;
              body = (e as { body?: string }).body ?? '';
            }
          } else {
            const r = await consoleFetch(`${gw.url}/machines/${m.id}${p.path}`, {
              method: p.method,
              headers: { Cookie: cookie },
              body: p.body,
            });
            status = r.status;
            body = await r.text();
          }
          // A read the family shares (upstream-http.ts) may be answered from another role's
          // request made just before: it counts as reaching the controller once.
          const shared = (gw.gw.upstreamStats(m.id)?.sharedAnswers ?? 0) - sharedBefore;
          // A socket the family shares (streams.ts) joins the one upstream socket: it counts once
          // whether it opened that socket or joined it.
          const joined = gw.gw.streamStats(m.id).joined - joinsBefore;
          const reached = joined
            ? joined + forwarded(fam, stub.seen) - (before - wsBefore)
            : forwarded(fam, stub.seen) + stub.wsSeen.length - before + shared;
          expect(stub.wsSeen.length - wsBefore, label).toBeLessThanOrEqual(1);
          // A socket the family does not declare (streams) is refused before anything reaches it.
          const undeclaredSocket =
            p.ws && !(fam.gateway?.sharing?.streams ?? []).some((d) => d.matches(p.path));
          if (allowed && undeclaredSocket) {
            expect({ label, status, reached }).toEqual({ label, status: 404, reached: 0 });
          } else if (allowed) {
            expect({ label, status, reached }).toEqual({ label, status: p.ws ? 101 : 200, reached: 1 });
          } else {
            expect({ label, status, reached }).toEqual({ label, status: 403, reached: 0 });
            // A request classified by its body is refused before the body is read, with the least
            // role any body could need (operator) when the user is below that.
            const said = (JSON.parse(body) as { needs: string }).needs;
            expect(
              said === need ||
                (p.body !== undefined && !roleAtLeast(role, 'operator') && said === 'operator'),
              `${label}: needs ${said}`,
            ).toBe(true);
          }
          // No configured secret ever comes back.
          expect(body).not.toContain('family-test-api-key');
          expect(body).not.toContain('family-test-password');
        }
      }
    });
  }
});
