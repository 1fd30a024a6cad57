import http from 'node:http';
import type { AddressInfo } from 'node:net';
import path from 'node:path';
import bcrypt from 'bcryptjs';
import type { WebSocket } from 'ws';
import { afterEach, describe, expect, it, vi } from 'vitest';
import { main as userCommand } from '../scripts/user';
import { createApi } from './api';
import type { AuditEntry } from './audit';
import { createContext, RefusalAggregator, type GatewayOptions } from './context';
import type { MachineEntry } from './machines';
import { hashFast, openWs, startGateway, tempDir, testFamily, user, writeJson } from './test-util';
import { DEFAULT_COST, UserDirectory, writeUsers, type UserRecord } from './users';

/**
 * The pen test's attacks on the login, the PIN unlock and the audit log, each performed against
 * the real gateway on a real HTTP server (several client addresses: 127.0.0.x), with a fake clock.
 */

const cleanups: Array<() => Promise<void> | void> = [];
afterEach(async () => {
  vi.restoreAllMocks();
  for (const c of cleanups.splice(0).reverse()) await c();
});

const PW = {
  vera: 'viewer-pass-1',
  otto: 'operator-pass-1',
  olga: 'operator-pass-2',
  sam: 'supervisor-pass-1',
  sue: 'supervisor-pass-2',
  old: 'supervisor-pass-3',
};
const PIN = { sam: '604321', sue: '918273' };

function defaultUsers(): UserRecord[] {
  return [
    user('vera', 'viewer', PW.vera),
    user('otto', 'operator', PW.otto),
    user('olga', 'operator', PW.olga),
    user('sam', 'supervisor', PW.sam, { pinHash: hashFast(PIN.sam) }),
    user('sue', 'supervisor', PW.sue, { pinHash: hashFast(PIN.sue) }),
    // A PIN set before PINs needed 6 digits.
    user('old', 'supervisor', PW.old, { pinHash: hashFast('4711') }),
  ];
}

const LIMITS = {
  windowMs: 15 * 60_000,
  perUser: 5,
  perAddress: 20,
  perPin: 5,
  perPinOperator: 10,
  perPinTotal: 30,
  perUserTotal: 50,
};

function machine(id: string, simulated: boolean): MachineEntry {
  return {
    id,
    name: id,
    kind: 'prunt',
    simulated,
    url: simulated ? null : new URL('http://127.0.0.1:9'),
    wsUrl: null,
    secrets: {},
  };
}

interface Setup {
  base: string;
  clock: { t: number };
  usersFile: string;
  dir: string;
  audit(): AuditEntry[];
}

function options(dir: string, usersFile: string, clock: { t: number }, rateLimit = {}): GatewayOptions {
  return {
    machines: { file: null, machines: [machine('p1', false), machine('demo', true)] },
    families: { prunt: testFamily('prunt') },
    dataDir: dir,
    usersFile,
    env: {},
    now: () => clock.t,
    rateLimit: { ...LIMITS, ...rateLimit },
  };
}

async function setup(o: { users?: UserRecord[]; rateLimit?: Record<string, number> } = {}): Promise<Setup> {
  const t = tempDir();
  cleanups.push(t.cleanup);
  const usersFile = path.join(t.dir, 'users.json');
  writeJson(usersFile, { users: o.users ?? defaultUsers() });
  const clock = { t: Date.parse('2026-01-05T08:00:00Z') };
  const gw = await startGateway(options(t.dir, usersFile, clock, o.rateLimit));
  cleanups.push(gw.close);
  return { base: gw.url, clock, usersFile, dir: t.dir, audit: () => gw.gw.audit.all() };
}

interface Reply {
  status: number;
  headers: http.IncomingHttpHeaders;
  body: Record<string, unknown>;
  cookie: string;
}

/** One request on its own connection, from a chosen local address (127.0.0.x). */
function request(
  base: string,
  method: string,
  p: string,
  o: { body?: unknown; cookie?: string; from?: string } = {},
): Promise<Reply> {
  const url = new URL(p, base);
  const text = o.body === undefined ? undefined : JSON.stringify(o.body);
  return new Promise((resolve, reject) => {
    const req = http.request(
      {
        host: url.hostname,
        port: url.port,
        path: url.pathname + url.search,
        method,
        agent: false,
        localAddress: o.from ?? '127.0.0.1',
        headers: {
          // The console's own page sends this on every state-changing request (csrf.ts).
          ...(method !== 'GET' ? { 'X-Shopdeck': '1' } : {}),
          ...(text !== undefined
            ? { 'Content-Type': 'application/json', 'Content-Length': Buffer.byteLength(text) }
            : {}),
          ...(o.cookie ? { Cookie: o.cookie } : {}),
        },
      },
      (res) => {
        const chunks: Buffer[] = [];
        res.on('data', (c: Buffer) => chunks.push(c));
        res.on('end', () => {
          const raw = Buffer.concat(chunks).toString('utf8');
          let body: Record<string, unknown> = {};
          try {
            body = JSON.parse(raw) as Record<string, unknown>;
          } catch {
            body = { raw };
          }
          const set = res.headers['set-cookie']?.[0] ?? '';
          resolve({
            status: res.statusCode ?? 0,
            headers: res.headers,
            body,
            cookie: set.split(';')[0] ?? '',
          });
        });
      },
    );
    req.on('error', reject);
    req.end(text);
  });
}

const loginAs = (s: Setup, name: string, password: string, from?: string) =>
  request(s.base, 'POST', '/api/login', { body: { name, password }, from });

async function sessionOf(s: Setup, name: keyof typeof PW, from?: string): Promise<string> {
  const r = await loginAs(s, name, PW[name], from);
  expect([r.status, r.body], `login ${name}`).toEqual([200, r.body]);
  return r.cookie;
}

const elevate = (s: Setup, cookie: string, name: string, pin: string, from?: string) =>
  request(s.base, 'POST', '/api/elevate', { body: { name, pin }, cookie, from });

const originalCompare = bcrypt.compare;

/** Counts bcrypt comparisons (and the hashes compared against); they run as usual. */
function countCompares(): { hashes: string[] } {
  const hashes: string[] = [];
  vi.spyOn(bcrypt, 'compare').mockImplementation(((secret: string, hash: string) => {
    hashes.push(hash);
    return originalCompare(secret, hash);
  }) as typeof bcrypt.compare);
  return { hashes };
}

/**
 * Holds every bcrypt comparison until `open()`: the slow hash of a real deployment, made as
 * slow as needed so that concurrent guesses really overlap.
 */
function gateCompares(): { hashes: string[]; open(): void } {
  let open!: () => void;
  const gate = new Promise<void>((r) => (open = r));
  const hashes: string[] = [];
  vi.spyOn(bcrypt, 'compare').mockImplementation((async (secret: string, hash: string) => {
    hashes.push(hash);
    await gate;
    return originalCompare(secret, hash);
  }) as typeof bcrypt.compare);
  return { hashes, open };
}

async function until(cond: () => boolean, what: string): Promise<void> {
  const deadline = Date.now() + 5000;
  while (!cond()) {
    if (Date.now() > deadline) throw new Error(`timed out waiting for ${what}`);
    await new Promise((r) => setTimeout(r, 5));
  }
}

/** Fires `guesses` at once; once every one is answered or stuck in bcrypt, fires `right`. */
async function race(
  guesses: Array<() => Promise<Reply>>,
  right: () => Promise<Reply>,
  g: { hashes: string[]; open(): void },
): Promise<{ statuses: number[]; right: Reply }> {
  let answered = 0;
  const all = guesses.map((f) =>
    f().then((r) => {
      answered++;
      return r;
    }),
  );
  await until(() => answered + g.hashes.length === guesses.length, 'every guess to be answered or evaluated');
  let rightDone = false;
  const last = right().then((r) => {
    rightDone = true;
    return r;
  });
  await until(() => rightDone || g.hashes.length > guesses.length - answered, 'the right secret');
  g.open();
  return { statuses: (await Promise.all(all)).map((r) => r.status), right: await last };
}

const count = (list: number[], status: number) => list.filter((x) => x === status).length;

// ------------------------------------------------------------------------------------------

describe('1. guesses do not race the limiter', () => {
  it('40 concurrent PINs from one operator session: at most 5 evaluated, the rest 429, the right PIN refused', async () => {
    const s = await setup();
    const op = await sessionOf(s, 'otto');
    const g = gateCompares();
    const wrong = Array.from({ length: 40 }, (_, i) => () => elevate(s, op, 'sam', String(430000 + i)));
    const r = await race(wrong, () => elevate(s, op, 'sam', PIN.sam), g);
    expect(g.hashes.length).toBeLessThanOrEqual(5);
    expect(count(r.statuses, 401)).toBe(g.hashes.length);
    expect(count(r.statuses, 429)).toBe(40 - g.hashes.length);
    expect(r.right.status).toBe(429);
    // Still the operator: the unlock did not happen.
    const me = await request(s.base, 'GET', '/api/session', { cookie: op });
    expect(me.body).toMatchObject({ user: { name: 'otto', role: 'operator' }, elevation: null });
  });

  it('24 concurrent wrong passwords: at most 5 evaluated, the rest 429, the right password refused', async () => {
    const s = await setup();
    const g = gateCompares();
    const wrong = Array.from({ length: 24 }, (_, i) => () => loginAs(s, 'otto', `guess-${i}`));
    const r = await race(wrong, () => loginAs(s, 'otto', PW.otto), g);
    expect(g.hashes.length).toBeLessThanOrEqual(5);
    expect(count(r.statuses, 401)).toBe(g.hashes.length);
    expect(count(r.statuses, 429)).toBe(24 - g.hashes.length);
    expect(r.right.status).toBe(429);
    expect(r.right.cookie).toBe('');
  });

  it('a correct attempt gives its slot back: four typos and a success leave room', async () => {
    const s = await setup();
    for (let i = 0; i < 4; i++) expect((await loginAs(s, 'otto', `typo-${i}`)).status).toBe(401);
    expect((await loginAs(s, 'otto', PW.otto)).status).toBe(200);
    expect((await loginAs(s, 'otto', 'typo-again')).status).toBe(401);
  });
});

describe('2. wrong PINs lock the tablet that tried them, not the supervisor’s PIN for everyone', () => {
  it('an operator’s five wrong PINs do not stop a supervisor’s PIN on another operator’s tablet', async () => {
    // The attack of the pen test: from one tablet, five wrong PINs for every supervisor.
    const s = await setup();
    const otto = await sessionOf(s, 'otto', '127.0.0.10');
    const olga = await sessionOf(s, 'olga', '127.0.0.11');
    for (const sup of ['sam', 'sue'])
      for (let i = 0; i < 5; i++) {
        const r = await elevate(s, otto, sup, String(111111 * (i + 1)), '127.0.0.10');
        expect(r.status === 401 || r.status === 429).toBe(true);
      }
    // Otto's tablet is locked, whichever the supervisor (the right PIN too).
    const locked = await elevate(s, otto, 'sam', PIN.sam, '127.0.0.10');
    expect(locked.status).toBe(429);
    expect(Number(locked.headers['retry-after'])).toBeGreaterThan(0);
    // Olga's tablet: both supervisors' PINs work, and their passwords.
    expect((await elevate(s, olga, 'sam', PIN.sam, '127.0.0.11')).status).toBe(200);
    expect((await elevate(s, olga, 'sue', PIN.sue, '127.0.0.11')).status).toBe(200);
    expect((await loginAs(s, 'sam', PW.sam, '127.0.0.12')).status).toBe(200);
    // Audited once, when it happened: the tablet, not a supervisor's PIN, is locked.
    const notes = s
      .audit()
      .filter((e) => e.type === 'elevate-failed' && /may try no PIN/.test(e.error ?? ''));
    expect(notes).toHaveLength(1);
    expect(notes[0]).toMatchObject({ onBehalfOf: 'otto' });
    expect(notes[0]?.error).toMatch(/this tablet \(otto at 127\.0\.0\.10\)/);
    // The lock ends with the window.
    s.clock.t += LIMITS.windowMs + 1000;
    const again = await sessionOf(s, 'otto', '127.0.0.10');
    expect((await elevate(s, again, 'sam', PIN.sam, '127.0.0.10')).status).toBe(200);
  });

  it('wrong PINs do not lock the logins from the tablet’s address', async () => {
    // The per-address limit as low as the per-tablet one: a shared counter would lock the logins.
    const s = await setup({ rateLimit: { perAddress: 5 } });
    const otto = await sessionOf(s, 'otto', '127.0.0.30');
    for (let i = 0; i < 5; i++) await elevate(s, otto, 'sam', String(500000 + i), '127.0.0.30');
    for (let i = 0; i < 5; i++) await elevate(s, otto, 'sue', String(600000 + i), '127.0.0.30');
    // Sam logs in on that tablet with the password.
    expect((await loginAs(s, 'sam', PW.sam, '127.0.0.30')).status).toBe(200);
  });

  it('an operator moving between addresses is limited per account', async () => {
    const s = await setup({ rateLimit: { perAddress: 100 } });
    const otto = await sessionOf(s, 'otto');
    for (let i = 0; i < LIMITS.perPinOperator; i++)
      expect((await elevate(s, otto, 'sam', String(200000 + i), `127.0.1.${i + 1}`)).status).toBe(401);
    expect((await elevate(s, otto, 'sam', PIN.sam, '127.0.1.200')).status).toBe(429);
    const olga = await sessionOf(s, 'olga', '127.0.1.201');
    expect((await elevate(s, olga, 'sam', PIN.sam, '127.0.1.201')).status).toBe(200);
  });

  it('one PIN guessed from many tablets is capped; tablets the supervisor unlocked before still work', async () => {
    const s = await setup({ rateLimit: { perAddress: 1000, perPinOperator: 1000 } });
    const olga = await sessionOf(s, 'olga', '127.0.2.1');
    // Sam unlocked Olga's tablet once: that tablet is known to sam's PIN.
    expect((await elevate(s, olga, 'sam', PIN.sam, '127.0.2.1')).status).toBe(200);
    // A distributed guesser: 4 wrong PINs from each of many addresses (never the per-tablet 5).
    const otto = await sessionOf(s, 'otto');
    let guesses = 0;
    for (let a = 10; guesses < LIMITS.perPinTotal; a++)
      for (let i = 0; i < 4 && guesses < LIMITS.perPinTotal; i++, guesses++)
        expect((await elevate(s, otto, 'sam', String(300000 + guesses), `127.0.2.${a}`)).status).toBe(401);
    // The next guess from a fresh address is refused without evaluation…
    const capped = await elevate(s, otto, 'sam', PIN.sam, '127.0.2.200');
    expect(capped.status).toBe(429);
    // …but sam's PIN still unlocks the tablet sam used before, and sam's password works.
    expect((await elevate(s, olga, 'sam', PIN.sam, '127.0.2.1')).status).toBe(200);
    expect((await loginAs(s, 'sam', PW.sam, '127.0.2.201')).status).toBe(200);
    // Another supervisor's PIN is not affected anywhere.
    expect((await elevate(s, otto, 'sue', PIN.sue, '127.0.2.202')).status).toBe(200);
    expect(
      s.audit().some((e) => e.type === 'elevate-failed' && /PIN of sam is refused/.test(e.error ?? '')),
    ).toBe(true);
  });
});

describe('3. PINs have at least 6 digits', () => {
  it('the gateway refuses a short PIN without evaluating it, and counts it as an attempt', async () => {
    const s = await setup();
    const op = await sessionOf(s, 'otto');
    const c = countCompares();
    // A PIN stored before the rule: refused without being compared.
    const legacy = await elevate(s, op, 'old', '4711');
    expect(legacy.status).toBe(401);
    expect(String(legacy.body.error)).toMatch(/6 to 12 digits/);
    expect(c.hashes).toHaveLength(0);
    // Short guesses are not compared but count: with the legacy one, five lock this tablet.
    for (let i = 0; i < 4; i++) expect((await elevate(s, op, 'sue', '1234')).status).toBe(401);
    expect(c.hashes).toHaveLength(0);
    expect((await elevate(s, op, 'sue', PIN.sue)).status).toBe(429);
    expect(c.hashes).toHaveLength(0);
    expect(
      s.audit().filter((e) => e.type === 'elevate-failed' && /6 to 12 digits/.test(e.error ?? '')),
    ).toHaveLength(5);
  });

  it('npm run user refuses PINs shorter than 6 digits or not digits', async () => {
    const t = tempDir();
    cleanups.push(t.cleanup);
    const e = { SHOPDECK_DATA: t.dir, SHOPDECK_BCRYPT_COST: '4' };
    const input = (...lines: string[]) => ({ line: (i: number) => Promise.resolve(lines[i] ?? '') });
    for (const bad of ['12345', '4711', 'abcdef', '12345a', '1234567890123']) {
      await expect(
        userCommand(
          ['add', 'sam', '--role', 'supervisor', '--pin', '--password-stdin'],
          e,
          input(PW.sam, bad),
        ),
      ).rejects.toThrow(/PIN must be 6 to 12 digits/);
    }
    await userCommand(
      ['add', 'sam', '--role', 'supervisor', '--pin', '--password-stdin'],
      e,
      input(PW.sam, '123456'),
    );
    await expect(userCommand(['pin', 'sam', '--password-stdin'], e, input('98765'))).rejects.toThrow(
      /PIN must be 6 to 12 digits/,
    );
    expect(await userCommand(['pin', 'sam', '--password-stdin'], e, input('987654'))).toBe('sam: PIN set');
  });
});

describe('4. only operators’ sessions can be unlocked', () => {
  for (const who of ['vera', 'sam'] as const) {
    it(`${who} (${who === 'vera' ? 'viewer' : 'supervisor'}) gets 403 without any PIN being evaluated`, async () => {
      const s = await setup();
      const cookie = await sessionOf(s, who);
      const c = countCompares();
      const r = await elevate(s, cookie, 'sue', PIN.sue);
      expect(r.status).toBe(403);
      expect(c.hashes).toHaveLength(0);
      const me = await request(s.base, 'GET', '/api/session', { cookie });
      expect(me.body).toMatchObject({ user: { name: who }, elevation: null });
      expect(s.audit().filter((e) => e.type === 'elevate-failed')).toMatchObject([
        { result: 'refused', user: 'sue', onBehalfOf: who },
      ]);
    });
  }
});

describe('5. an attacker hammering a user does not lock the real user out', () => {
  it('the right password from another address still works', async () => {
    const s = await setup();
    for (let i = 0; i < 5; i++)
      expect((await loginAs(s, 'otto', `guess-${i}`, '127.0.0.66')).status).toBe(401);
    expect((await loginAs(s, 'otto', 'guess-5', '127.0.0.66')).status).toBe(429);
    expect((await loginAs(s, 'otto', PW.otto, '127.0.0.66')).status).toBe(429);
    // The real otto, at the tablet.
    expect((await loginAs(s, 'otto', PW.otto, '127.0.0.1')).status).toBe(200);
  });

  it('the per-user backstop (many addresses) spares the addresses the user logged in from', async () => {
    const s = await setup({ rateLimit: { perUser: 3, perUserTotal: 12 } });
    await sessionOf(s, 'otto', '127.0.0.1');
    for (let a = 0; a < 4; a++)
      for (let i = 0; i < 3; i++)
        expect((await loginAs(s, 'otto', `guess-${a}-${i}`, `127.0.0.${100 + a}`)).status).toBe(401);
    // 12 failures from 4 addresses: new addresses are refused for otto...
    expect((await loginAs(s, 'otto', 'guess-x', '127.0.0.120')).status).toBe(429);
    // ...other users are not...
    expect((await loginAs(s, 'vera', PW.vera, '127.0.0.120')).status).toBe(200);
    // ...and otto at his tablet gets in.
    expect((await loginAs(s, 'otto', PW.otto, '127.0.0.1')).status).toBe(200);
  });
});

describe('6. unknown names cost the same bcrypt work as real ones', () => {
  it('the dummy hash has the users’ cost (read from the file)', async () => {
    const users = defaultUsers().map((u) => ({
      ...u,
      passwordHash: bcrypt.hashSync(PW[u.name as keyof typeof PW], 5),
    }));
    const s = await setup({ users });
    const c = countCompares();
    expect((await loginAs(s, 'nobody-here', 'whatever-1')).status).toBe(401);
    expect((await loginAs(s, 'otto', 'whatever-1')).status).toBe(401);
    const cost = (h: string | undefined) => /^\$2[aby]\$(\d\d)\$/.exec(h ?? '')?.[1];
    expect(c.hashes).toHaveLength(2);
    expect(cost(c.hashes[0])).toBe('05');
    expect(cost(c.hashes[0])).toBe(cost(c.hashes[1]));
    // PINs: the unknown supervisor is compared against a dummy with the PIN hashes' cost (4).
    const op = await sessionOf(s, 'otto');
    c.hashes.length = 0;
    expect((await elevate(s, op, 'nobody-here', '123456')).status).toBe(401);
    expect((await elevate(s, op, 'otto', '123456')).status).toBe(401);
    expect(c.hashes.map(cost)).toEqual(['04', '04']);
  });

  it('with no hash to read, the dummy has hashSecret’s default cost', async () => {
    const t = tempDir();
    cleanups.push(t.cleanup);
    const file = path.join(t.dir, 'users.json');
    writeJson(file, { users: [] });
    const dir = new UserDirectory(file);
    expect(dir.dummyHash('password')).toMatch(
      new RegExp(`^\\$2b\\$${String(DEFAULT_COST).padStart(2, '0')}\\$`),
    );
    expect(dir.dummyHash('password')).toHaveLength(60);
    writeUsers(file, [{ ...user('x', 'viewer', 'x'), passwordHash: bcrypt.hashSync('x', 6) }]);
    // The directory sees the change when the file system reports it (users.ts), not in this turn.
    for (let i = 0; i < 500 && !dir.dummyHash('password').startsWith('$2b$06$'); i++)
      await new Promise((r) => setTimeout(r, 10));
    dir.close();
    expect(dir.dummyHash('password')).toMatch(/^\$2b\$06\$/);
    expect(dir.dummyHash('pin')).toMatch(/^\$2b\$06\$/);
  });
});

describe('7. a changed role takes effect on live sessions', () => {
  it('a promoted operator gets the supervisor idle timeout at once (audited)', async () => {
    const s = await setup();
    const op = await sessionOf(s, 'otto');
    expect((await request(s.base, 'GET', '/api/session', { cookie: op })).body).toMatchObject({
      idleTimeoutS: 12 * 3600,
    });
    writeUsers(
      s.usersFile,
      defaultUsers().map((u) => (u.name === 'otto' ? { ...u, role: 'supervisor' } : u)),
    );
    const now = await request(s.base, 'GET', '/api/session', { cookie: op });
    expect(now.body).toMatchObject({ user: { name: 'otto', role: 'supervisor' }, idleTimeoutS: 3600 });
    expect(s.audit().filter((e) => e.type === 'role-change')).toMatchObject([
      { user: 'otto', role: 'supervisor', source: 'gateway', result: 'ok' },
    ]);
    expect(s.audit().find((e) => e.type === 'role-change')?.detail).toMatch(/operator → supervisor/);
    s.clock.t += 61 * 60_000;
    expect((await request(s.base, 'GET', '/api/machines', { cookie: op })).status).toBe(401);
  });

  it('an unlock ends when the tablet’s user is no longer an operator', async () => {
    const s = await setup();
    const op = await sessionOf(s, 'otto');
    expect((await elevate(s, op, 'sam', PIN.sam)).status).toBe(200);
    writeUsers(
      s.usersFile,
      defaultUsers().map((u) => (u.name === 'otto' ? { ...u, role: 'viewer' as const } : u)),
    );
    expect((await request(s.base, 'GET', '/api/session', { cookie: op })).body).toMatchObject({
      user: { name: 'otto', role: 'viewer' },
      elevation: null,
    });
    expect(s.audit().filter((e) => e.type === 'elevate-end')).toMatchObject([
      { user: 'sam', onBehalfOf: 'otto', source: 'gateway' },
    ]);
  });

  it('a demoted supervisor’s console socket (real WebSocket, simulated machine) closes', async () => {
    const s = await setup();
    const sam = await sessionOf(s, 'sam');
    const vera = await sessionOf(s, 'vera');
    const ws = await openWs(`${s.base.replace('http', 'ws')}/machines/demo/console`, {
      Cookie: sam,
      Origin: s.base,
    });
    const closed = new Promise<number>((r) => ws.ws.once('close', (code) => r(code)));
    writeUsers(
      s.usersFile,
      defaultUsers().map((u) => (u.name === 'sam' ? { ...u, role: 'operator' as const } : u)),
    );
    // Anyone's request makes the gateway notice.
    await request(s.base, 'GET', '/api/session', { cookie: vera });
    expect(await closed).toBe(4401);
  });

  it('a demoted or removed user’s bridged sockets are re-checked (closed)', async () => {
    const t = tempDir();
    cleanups.push(t.cleanup);
    const usersFile = path.join(t.dir, 'users.json');
    writeUsers(usersFile, defaultUsers());
    const clock = { t: Date.parse('2026-01-05T08:00:00Z') };
    const ctx = createContext(options(t.dir, usersFile, clock));
    const api = createApi(ctx);
    const server = http.createServer((req, res) => {
      void api(req, res, new URL(req.url ?? '/', 'http://gateway.local'));
    });
    await new Promise<void>((r) => server.listen(0, '127.0.0.1', () => r()));
    cleanups.push(() => new Promise<void>((r) => server.close(() => r())));
    const s: Setup = {
      base: `http://127.0.0.1:${(server.address() as AddressInfo).port}`,
      clock,
      usersFile,
      dir: t.dir,
      audit: () => ctx.audit.all(),
    };
    const sam = await sessionOf(s, 'sam');
    const otto = await sessionOf(s, 'otto');
    const closed: string[] = [];
    const live = (token: string, needs: 'supervisor' | 'viewer', tag: string) =>
      ctx.liveSockets.set({ tag } as unknown as WebSocket, {
        machine: 'p1',
        token,
        needs,
        close: (_code, reason) => closed.push(`${tag}: ${reason}`),
      });
    live(sam.split('=')[1]!, 'supervisor', 'sam console');
    live(otto.split('=')[1]!, 'viewer', 'otto status');
    // sam is demoted: seen on any request (here otto's), sam's console socket closes.
    writeUsers(
      usersFile,
      defaultUsers().map((u) => (u.name === 'sam' ? { ...u, role: 'operator' as const } : u)),
    );
    await request(s.base, 'GET', '/api/session', { cookie: otto });
    expect(closed).toEqual(['sam console: sam no longer has the supervisor role']);
    expect(s.audit().filter((e) => e.type === 'role-change')).toMatchObject([
      { user: 'sam', role: 'operator', source: 'gateway' },
    ]);
    // otto is removed: his session and sockets end.
    writeUsers(
      usersFile,
      defaultUsers().filter((u) => u.name !== 'otto'),
    );
    expect((await request(s.base, 'GET', '/api/session', { cookie: sam })).status).toBe(200);
    expect(closed).toEqual(['sam console: sam no longer has the supervisor role', 'otto status: logged out']);
    expect((await request(s.base, 'GET', '/api/session', { cookie: otto })).body).toMatchObject({
      user: null,
    });
  });
});

describe('8. client audit records', () => {
  it('the browser cannot write audit entries: the gateway records simulated machines itself', async () => {
    const s = await setup();
    const op = await sessionOf(s, 'otto');
    const rec = { machine: 'demo', command: 'job.pause', label: 'pause', ok: true };
    expect((await request(s.base, 'POST', '/api/audit/client', { body: rec, cookie: op })).status).toBe(404);
    expect(s.audit().filter((e) => e.source === 'client')).toEqual([]);
  });
});

describe('9. refusals of unauthenticated clients do not flood the audit log', () => {
  it('per address: the first 10 a minute are written, the rest as one summary', async () => {
    const s = await setup();
    const refusedNow = () => s.audit().filter((e) => e.type === 'refused');
    for (let i = 0; i < 30; i++) {
      const r = await request(s.base, 'POST', '/machines/demo/settings', { body: {}, from: '127.0.0.50' });
      expect(r.status).toBe(401);
    }
    expect(
      (await request(s.base, 'POST', '/machines/demo/settings', { body: {}, from: '127.0.0.51' })).status,
    ).toBe(401);
    expect(refusedNow().filter((e) => e.address === '127.0.0.50')).toHaveLength(10);
    expect(refusedNow().filter((e) => e.address === '127.0.0.51')).toHaveLength(1);
    s.clock.t += 61_000;
    await request(s.base, 'POST', '/machines/demo/settings', { body: {}, from: '127.0.0.50' });
    const list = refusedNow().filter((e) => e.address === '127.0.0.50');
    expect(list).toHaveLength(12);
    expect(list[10]).toMatchObject({ user: 'nobody', result: 'refused' });
    expect(list[10]?.detail).toBe('20 more refused requests from 127.0.0.50 in the last minute');
    expect(list[11]?.detail).toBeUndefined();
  });

  it('logins refused by the limiter (429) are aggregated too', async () => {
    const s = await setup();
    for (let i = 0; i < 25; i++) await loginAs(s, 'otto', `guess-${i}`, '127.0.0.60');
    const failed = s.audit().filter((e) => e.type === 'login-failed');
    expect(failed.filter((e) => e.result === 'failed')).toHaveLength(5);
    expect(failed.filter((e) => e.result === 'refused')).toHaveLength(10);
  });

  it('the aggregator writes the summary when the window ends (timer or next record)', () => {
    const clock = { t: 0 };
    const out: Array<Record<string, unknown>> = [];
    const agg = new RefusalAggregator(
      { windowMs: 60_000, firstN: 2 },
      () => clock.t,
      (e) => out.push(e as unknown as Record<string, unknown>),
    );
    const e = {
      type: 'refused' as const,
      result: 'refused' as const,
      user: 'nobody',
      source: 'gateway' as const,
    };
    expect([1, 2, 3, 4].map(() => agg.admit({ ...e, address: '10.0.0.1' }))).toEqual([
      true,
      true,
      false,
      false,
    ]);
    expect(agg.admit({ ...e, user: 'otto', address: '10.0.0.1' })).toBe(true);
    agg.flush();
    expect(out).toHaveLength(0);
    clock.t = 60_000;
    agg.flush();
    expect(out).toMatchObject([
      {
        type: 'refused',
        user: 'nobody',
        address: '10.0.0.1',
        detail: '2 more refused requests from 10.0.0.1 in the last minute',
      },
    ]);
    agg.flush();
    expect(out).toHaveLength(1);
    agg.dispose();
  });
});

describe('other holes of the same kind', () => {
  it('logging in over an existing session ends that session (no session left behind)', async () => {
    const s = await setup();
    const first = await sessionOf(s, 'otto');
    const r = await request(s.base, 'POST', '/api/login', {
      body: { name: 'vera', password: PW.vera },
      cookie: first,
    });
    expect(r.status).toBe(200);
    expect((await request(s.base, 'GET', '/api/session', { cookie: first })).body).toMatchObject({
      user: null,
    });
  });

  it('DELETE /api/elevate ends only the caller’s own unlock', async () => {
    const s = await setup();
    const op = await sessionOf(s, 'otto');
    const other = await sessionOf(s, 'vera');
    expect((await elevate(s, op, 'sam', PIN.sam)).status).toBe(200);
    await request(s.base, 'DELETE', '/api/elevate', { cookie: other });
    expect((await request(s.base, 'GET', '/api/session', { cookie: op })).body).toMatchObject({
      elevation: { supervisor: 'sam' },
    });
    await request(s.base, 'DELETE', '/api/elevate', { cookie: op });
    expect((await request(s.base, 'GET', '/api/session', { cookie: op })).body).toMatchObject({
      elevation: null,
    });
  });
});
