import { afterEach, describe, expect, it } from 'vitest';
import { roleAtLeast, ROLES, type Role } from '../src/fleet/types';
import type { AuditEntry } from './audit';
import type { MachineEntry } from './machines';
import {
  hashFast,
  login,
  openWs,
  user,
  type Running,
  type Stub,
  consoleFetch,
  stubFor,
  gatewayFor,
  stubEntry,
  writeJson,
} from './test-util';
import type { UserRecord } from './users';

const cleanups: Array<() => Promise<void> | void> = [];
afterEach(async () => {
  for (const c of cleanups.splice(0).reverse()) await c();
});

const PASSWORDS: Record<string, string> = {
  vera: 'viewer-pass-1',
  otto: 'operator-pass-1',
  sam: 'supervisor-pass-1',
};

function defaultUsers(): UserRecord[] {
  return [
    user('vera', 'viewer', PASSWORDS.vera!),
    user('otto', 'operator', PASSWORDS.otto!),
    user('sam', 'supervisor', PASSWORDS.sam!, { pinHash: hashFast('471147') }),
    user('lena', 'operator', 'limited-pass-1', { machines: ['p2'] }),
    user('rita', 'supervisor', 'limited-pass-2', { machines: ['p2'] }),
  ];
}

interface Setup {
  gw: Running;
  stub: Stub;
  clock: { t: number };
  usersFile: string;
}

async function setup(opts: { users?: UserRecord[] | null; machines?: MachineEntry[] } = {}): Promise<Setup> {
  const stub = await stubFor(cleanups);
  const clock = { t: Date.parse('2026-01-05T08:00:00Z') };
  const gw = await gatewayFor(
    cleanups,
    opts.machines ?? [
      stubEntry('p1', stub.url),
      stubEntry('p2', stub.url),
      stubEntry('demo', null, { simulated: true }),
    ],
    {
      users: opts.users === undefined ? defaultUsers() : opts.users,
      now: () => clock.t,
      rateLimit: { windowMs: 60_000, perUser: 3, perAddress: 6 },
    },
  );
  return { gw, stub, clock, usersFile: gw.usersFile };
}

/** Requests of the test family, one per role level, HTTP and WebSocket. */
const REQUESTS: Array<{
  name: string;
  needs: Role;
  method: string;
  path: string;
  body?: string;
  ws?: boolean;
}> = [
  { name: 'read status', needs: 'viewer', method: 'GET', path: '/status' },
  { name: 'pause (GET command)', needs: 'operator', method: 'GET', path: '/job?action=pause' },
  { name: 'M25 (classified by body)', needs: 'operator', method: 'POST', path: '/code', body: 'M25' },
  { name: 'G28 (classified by body)', needs: 'supervisor', method: 'POST', path: '/code', body: 'G28' },
  { name: 'settings', needs: 'supervisor', method: 'POST', path: '/settings', body: '{}' },
  { name: 'live socket', needs: 'viewer', method: 'GET', path: '/live', ws: true },
  { name: 'console socket', needs: 'supervisor', method: 'GET', path: '/console', ws: true },
];

async function send(
  s: Setup,
  cookie: string,
  r: (typeof REQUESTS)[number],
  machine = 'p1',
): Promise<{ status: number; body: unknown }> {
  if (r.ws) {
    try {
      const w = await openWs(
        `ws://${s.gw.host}/machines/${machine}${r.path}`,
        cookie ? { Cookie: cookie } : {},
      );
      await w.close();
      return { status: 101, body: null };
    } catch (e) {
      const err = e as { status?: number; body?: string };
      return { status: err.status ?? 0, body: err.body ? (JSON.parse(err.body) as unknown) : null };
    }
  }
  const res = await consoleFetch(`${s.gw.url}/machines/${machine}${r.path}`, {
    method: r.method,
    headers: cookie ? { Cookie: cookie } : {},
    body: r.body,
  });
  return { status: res.status, body: (await res.json()) as unknown };
}

describe('roles enforced at the gateway', () => {
  for (const role of ROLES) {
    it(`${role}: allowed exactly what the family declares for the role (HTTP and WebSocket)`, async () => {
      const s = await setup();
      const name = { viewer: 'vera', operator: 'otto', supervisor: 'sam' }[role];
      const cookie = await login(s.gw.url, name, PASSWORDS[name]!);
      for (const r of REQUESTS) {
        const before = s.stub.seen.length + s.stub.wsSeen.length;
        const got = await send(s, cookie, r);
        const reached = s.stub.seen.length + s.stub.wsSeen.length - before;
        if (roleAtLeast(role, r.needs)) {
          expect([r.name, got.status], r.name).toEqual([r.name, r.ws ? 101 : 200]);
          expect(reached, r.name).toBe(1);
        } else {
          expect([r.name, got.status]).toEqual([r.name, 403]);
          // A body-classified request is refused before its body is read, with the least role any
          // body could need (operator), when the user is below that.
          const byBody = r.path === '/code';
          const needs = byBody && !roleAtLeast(role, 'operator') ? 'operator' : r.needs;
          expect(got.body).toMatchObject({ needs });
          expect(reached, r.name).toBe(0);
        }
      }
      const refused = s.gw.gw.audit.all().filter((e) => e.type === 'refused');
      expect(refused.length).toBe(REQUESTS.filter((r) => !roleAtLeast(role, r.needs)).length);
      expect(refused.every((e) => e.user === name && e.result === 'refused')).toBe(true);
    });
  }

  it('refuses everything without a session, and the machine list too', async () => {
    const s = await setup();
    for (const r of REQUESTS) expect((await send(s, '', r)).status).toBe(401);
    expect((await consoleFetch(`${s.gw.url}/api/machines`)).status).toBe(401);
    expect(s.stub.seen).toHaveLength(0);
    expect(s.stub.wsSeen).toHaveLength(0);
  });

  it('applies the same rules to simulated machines', async () => {
    const s = await setup();
    const cookie = await login(s.gw.url, 'vera', PASSWORDS.vera!);
    const pause = REQUESTS[1]!;
    expect((await send(s, cookie, pause, 'demo')).status).toBe(403);
    const op = await login(s.gw.url, 'otto', PASSWORDS.otto!);
    expect((await send(s, op, pause, 'demo')).status).toBe(200);
  });

  it('limits a user to their machines: in the list and in the proxy', async () => {
    const s = await setup();
    const cookie = await login(s.gw.url, 'lena', 'limited-pass-1');
    const list = (await (
      await consoleFetch(`${s.gw.url}/api/machines`, { headers: { Cookie: cookie } })
    ).json()) as {
      machines: Array<{ id: string }>;
    };
    expect(list.machines.map((m) => m.id)).toEqual(['p2']);
    expect((await send(s, cookie, REQUESTS[0]!, 'p1')).status).toBe(403);
    expect((await send(s, cookie, REQUESTS[0]!, 'p2')).status).toBe(200);
    expect((await send(s, cookie, REQUESTS[5]!, 'p1')).status).toBe(403);
  });

  it('refuses cross-site commands and sockets', async () => {
    const s = await setup({ users: null });
    const r = await consoleFetch(`${s.gw.url}/machines/p1/settings`, {
      method: 'POST',
      body: '{}',
      headers: { Origin: 'http://evil.example' },
    });
    expect(r.status).toBe(403);
    await expect(
      openWs(`ws://${s.gw.host}/machines/p1/live`, { Origin: 'http://evil.example' }),
    ).rejects.toMatchObject({ status: 403 });
    const same = await consoleFetch(`${s.gw.url}/machines/p1/settings`, {
      method: 'POST',
      body: '{}',
      headers: { Origin: s.gw.url },
    });
    expect(same.status).toBe(200);
  });
});

describe('sessions', () => {
  it('sets an HttpOnly SameSite=Strict cookie and reports the session', async () => {
    const s = await setup();
    const r = await consoleFetch(`${s.gw.url}/api/login`, {
      method: 'POST',
      headers: { 'Content-Type': 'application/json' },
      body: JSON.stringify({ name: 'otto', password: PASSWORDS.otto }),
    });
    expect(r.status).toBe(200);
    const c = r.headers.getSetCookie()[0] ?? '';
    expect(c).toMatch(/^shopdeck_session=[A-Za-z0-9_-]{40,};/);
    expect(c).toContain('HttpOnly');
    expect(c).toContain('SameSite=Strict');
    const cookie = c.split(';')[0]!;
    const session = await (
      await consoleFetch(`${s.gw.url}/api/session`, { headers: { Cookie: cookie } })
    ).json();
    expect(session).toMatchObject({
      mode: 'secured',
      user: { name: 'otto', role: 'operator', machines: null },
      idleTimeoutS: 12 * 3600,
    });
    const out = await consoleFetch(`${s.gw.url}/api/logout`, { method: 'POST', headers: { Cookie: cookie } });
    expect(out.headers.getSetCookie()[0]).toContain('Max-Age=0');
    expect(
      await (await consoleFetch(`${s.gw.url}/api/session`, { headers: { Cookie: cookie } })).json(),
    ).toMatchObject({ user: null });
    const types = s.gw.gw.audit.all().map((e) => e.type);
    expect(types).toEqual(['login', 'logout']);
  });

  it('expires after the idle timeout of the role (fake clock); activity restarts it', async () => {
    const s = await setup();
    const op = await login(s.gw.url, 'otto', PASSWORDS.otto!);
    const sup = await login(s.gw.url, 'sam', PASSWORDS.sam!);
    const status = async (cookie: string) => (await send(s, cookie, REQUESTS[0]!)).status;
    s.clock.t += 59 * 60_000;
    expect(await status(sup)).toBe(200);
    // Reads (polling) are not activity: the supervisor's hour runs from login.
    s.clock.t += 2 * 60_000;
    expect(await status(sup)).toBe(401);
    const body = (await send(s, sup, REQUESTS[0]!)).body;
    expect(body).toMatchObject({ login: true });
    expect(s.gw.gw.audit.all().filter((e) => e.type === 'session-expired')).toMatchObject([
      { user: 'sam', result: 'ok' },
    ]);
    // The operator has 12 h; a command is activity and restarts the timer.
    s.clock.t += 10 * 3600_000;
    expect((await send(s, op, REQUESTS[1]!)).status).toBe(200);
    s.clock.t += 11 * 3600_000;
    expect(await status(op)).toBe(200);
    s.clock.t += 2 * 3600_000;
    expect(await status(op)).toBe(401);
  });

  it('rate-limits failed logins per user and per address', async () => {
    const s = await setup();
    const attempt = (name: string, password: string) =>
      consoleFetch(`${s.gw.url}/api/login`, {
        method: 'POST',
        headers: { 'Content-Type': 'application/json' },
        body: JSON.stringify({ name, password }),
      });
    for (let i = 0; i < 3; i++) expect((await attempt('otto', 'wrong')).status).toBe(401);
    // Locked: even the right password is refused now, without being checked.
    const locked = await attempt('otto', PASSWORDS.otto!);
    expect(locked.status).toBe(429);
    expect(Number(locked.headers.get('retry-after'))).toBeGreaterThan(0);
    // Another user from the same address is still fine (address limit 6).
    expect((await attempt('vera', PASSWORDS.vera!)).status).toBe(200);
    for (let i = 0; i < 3; i++) expect((await attempt(`nobody${i}`, 'x')).status).toBe(401);
    expect((await attempt('sam', PASSWORDS.sam!)).status).toBe(429);
    s.clock.t += 61_000;
    expect((await attempt('otto', PASSWORDS.otto!)).status).toBe(200);
    const failed = s.gw.gw.audit.all().filter((e) => e.type === 'login-failed');
    expect(failed.filter((e) => e.result === 'failed')).toHaveLength(6);
    expect(failed.filter((e) => e.result === 'refused')).toHaveLength(2);
  });

  it('PIN elevation: a supervisor acts on an operator tablet for a few minutes, then back', async () => {
    const s = await setup();
    const op = await login(s.gw.url, 'otto', PASSWORDS.otto!);
    const settings = REQUESTS[4]!;
    expect((await send(s, op, settings)).status).toBe(403);
    const elevate = (name: string, pin: string) =>
      consoleFetch(`${s.gw.url}/api/elevate`, {
        method: 'POST',
        headers: { 'Content-Type': 'application/json', Cookie: op },
        body: JSON.stringify({ name, pin }),
      });
    expect((await elevate('sam', '0000')).status).toBe(401);
    expect((await elevate('otto', '471147')).status).toBe(401);
    const ok = await elevate('sam', '471147');
    expect(ok.status).toBe(200);
    expect(await ok.json()).toMatchObject({
      user: { name: 'sam', role: 'supervisor' },
      elevation: { supervisor: 'sam', operator: { name: 'otto', role: 'operator' } },
    });
    expect((await send(s, op, settings)).status).toBe(200);
    const cmd = s.gw.gw.audit.all().find((e: AuditEntry) => e.type === 'command');
    expect(cmd).toMatchObject({ user: 'sam', onBehalfOf: 'otto', path: '/settings' });
    s.clock.t += 5 * 60_000 + 1;
    expect((await send(s, op, settings)).status).toBe(403);
    const back = await (await consoleFetch(`${s.gw.url}/api/session`, { headers: { Cookie: op } })).json();
    expect(back).toMatchObject({ user: { name: 'otto', role: 'operator' }, elevation: null });
    expect((await send(s, op, REQUESTS[1]!)).status).toBe(200);
  });

  it('open mode: no users file, everyone may do everything, and the session says so', async () => {
    const s = await setup({ users: null });
    expect(await (await consoleFetch(`${s.gw.url}/api/session`)).json()).toMatchObject({
      mode: 'open',
      user: null,
    });
    for (const r of REQUESTS) expect((await send(s, '', r)).status).toBe(r.ws ? 101 : 200);
    expect((await consoleFetch(`${s.gw.url}/api/machines`)).status).toBe(200);
    const login = await consoleFetch(`${s.gw.url}/api/login`, {
      method: 'POST',
      body: '{"name":"a","password":"b"}',
    });
    expect(login.status).toBe(400);
    expect(
      s.gw.gw.audit
        .all()
        .filter((e) => e.type === 'command')
        .every((e) => e.user === 'anonymous'),
    ).toBe(true);
  });

  it('turns secured when the first user is added while running', async () => {
    const s = await setup({ users: null });
    expect((await send(s, '', REQUESTS[4]!)).status).toBe(200);
    writeJson(s.usersFile, { users: [user('otto', 'operator', PASSWORDS.otto!)] });
    expect((await send(s, '', REQUESTS[4]!)).status).toBe(401);
    expect(await (await consoleFetch(`${s.gw.url}/api/session`)).json()).toMatchObject({ mode: 'secured' });
  });
});

describe('audit endpoints', () => {
  it('are for supervisors, filter, page and export CSV', async () => {
    const s = await setup();
    const op = await login(s.gw.url, 'otto', PASSWORDS.otto!);
    await send(s, op, REQUESTS[1]!);
    await send(s, op, REQUESTS[4]!); // refused
    const sup = await login(s.gw.url, 'sam', PASSWORDS.sam!);
    await send(s, sup, REQUESTS[4]!, 'p2');
    expect((await consoleFetch(`${s.gw.url}/api/audit`, { headers: { Cookie: op } })).status).toBe(403);
    const get = async (q: string) =>
      (await (await consoleFetch(`${s.gw.url}/api/audit${q}`, { headers: { Cookie: sup } })).json()) as {
        entries: AuditEntry[];
        total: number;
      };
    const all = await get('');
    // Newest first; the operator's own look at the audit log is the refused one on top.
    expect(all.entries.map((e) => e.type)).toEqual([
      'refused',
      'command',
      'login',
      'refused',
      'command',
      'login',
    ]);
    expect(all.entries[0]).toMatchObject({
      user: 'otto',
      method: 'GET',
      path: '/api/audit',
      role: 'supervisor',
    });
    expect((await get('?result=refused')).entries.map((e) => e.label ?? e.path)).toEqual([
      '/api/audit',
      'change settings',
    ]);
    expect((await get('?machine=p2')).total).toBe(1);
    expect((await get('?user=otto')).total).toBe(4);
    const page = await get('?offset=2&limit=2');
    expect(page.total).toBe(6);
    expect(page.entries.map((e) => e.type)).toEqual(['login', 'refused']);
    const to = new Date(s.clock.t - 1).toISOString();
    expect((await get(`?to=${encodeURIComponent(to)}`)).total).toBe(0);
    // A supervisor limited to some machines sees only their machines' commands.
    const rita = await login(s.gw.url, 'rita', 'limited-pass-2');
    const limited = (await (
      await consoleFetch(`${s.gw.url}/api/audit`, { headers: { Cookie: rita } })
    ).json()) as {
      entries: AuditEntry[];
    };
    expect(limited.entries.filter((e) => e.machine).map((e) => e.machine)).toEqual(['p2']);
    expect(limited.entries.filter((e) => e.type === 'login')).toHaveLength(3);
    const csv = await consoleFetch(`${s.gw.url}/api/audit.csv?user=otto`, { headers: { Cookie: sup } });
    expect(csv.headers.get('content-type')).toContain('text/csv');
    const bytes = new Uint8Array(await csv.arrayBuffer());
    expect([...bytes.slice(0, 3)]).toEqual([0xef, 0xbb, 0xbf]); // UTF-8 BOM: spreadsheets read it as UTF-8
    const lines = new TextDecoder().decode(bytes).trim().split('\r\n');
    expect(lines[0]).toMatch(/^time,type,result,user/);
    expect(lines).toHaveLength(5); // the header and otto's four entries
  });
});
