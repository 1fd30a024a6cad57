import path from 'node:path';
import Database from 'better-sqlite3';
import { afterEach, describe, expect, it } from 'vitest';
import {
  SESSION_TOUCH_WRITE_MS,
  SessionStore,
  SqliteSessionFile,
  tokenHash,
  type IdleTimeouts,
} from './auth';
import { consoleFetch, startGateway, tempDir, testFamily, user, writeJson } from './test-util';

/** The console sessions kept across restarts (auth.ts): in `<data>/history.sqlite`, hashed. */

const cleanups: Array<() => Promise<void> | void> = [];
afterEach(async () => {
  for (const c of cleanups.splice(0).reverse()) await c();
});

const IDLE: IdleTimeouts = { viewer: 600, operator: 600, supervisor: 60 };

function folder(): string {
  const t = tempDir();
  cleanups.push(t.cleanup);
  return path.join(t.dir, 'history.sqlite');
}

function store(file: string, clock: { t: number }): SessionStore {
  const f = new SqliteSessionFile(file);
  cleanups.push(() => f.close());
  return new SessionStore(IDLE, () => clock.t, f);
}

function rows(file: string): Array<Record<string, unknown>> {
  const db = new Database(file, { readonly: true });
  try {
    return db.prepare('SELECT * FROM sessions').all() as Array<Record<string, unknown>>;
  } finally {
    db.close();
  }
}

describe('SessionStore with its file', () => {
  it('keeps a session across a restart (a new store on the same file)', () => {
    const file = folder();
    const clock = { t: 1_000_000 };
    const s = store(file, clock).create('otto', 'operator');
    clock.t += 5_000;
    const again = store(file, clock).get(s.token);
    expect(again && !('expired' in again) ? again.user : null).toBe('otto');
    expect(again && !('expired' in again) ? again.role : null).toBe('operator');
  });

  it('stores only the SHA-256 of the token, never the token', () => {
    const file = folder();
    const s = store(file, { t: 1_000_000 }).create('sam', 'supervisor');
    const all = rows(file);
    expect(all).toHaveLength(1);
    expect(all[0]?.id).toBe(tokenHash(s.token));
    expect(tokenHash(s.token)).not.toBe(s.token);
    expect(JSON.stringify(all)).not.toContain(s.token);
  });

  it('a token that only matches the stored hash is refused (the hash is not a token)', () => {
    const file = folder();
    const clock = { t: 1_000_000 };
    const s = store(file, clock).create('otto', 'operator');
    expect(store(file, clock).get(tokenHash(s.token))).toBeNull();
  });

  it('the idle timeout holds across a restart: expired sessions are refused and deleted', () => {
    const file = folder();
    const clock = { t: 1_000_000 };
    const sup = store(file, clock).create('sam', 'supervisor');
    const op = store(file, clock).create('otto', 'operator');
    clock.t += 61_000; // past the supervisor's 60 s, within the operator's 600 s
    const after = store(file, clock);
    expect(after.get(sup.token)).toBeNull();
    expect(after.get(op.token)).not.toBeNull();
    expect(rows(file).map((r) => r.user)).toEqual(['otto']);
  });

  it('activity is written (at most every minute) and counts after a restart', () => {
    const file = folder();
    const clock = { t: 1_000_000 };
    const a = store(file, clock);
    const s = a.create('otto', 'operator');
    clock.t += SESSION_TOUCH_WRITE_MS;
    a.get(s.token); // touched and written
    clock.t += 550_000; // 610 s after login, 550 s after the last activity
    const b = store(file, clock).get(s.token);
    expect(b && !('expired' in b)).toBe(true);
  });

  it('logout and a removed user end the kept sessions', () => {
    const file = folder();
    const clock = { t: 1_000_000 };
    const a = store(file, clock);
    const one = a.create('otto', 'operator');
    const two = a.create('vera', 'viewer');
    const three = a.create('vera', 'viewer');
    a.delete(one.token);
    expect(a.dropUser('vera')).toBe(2);
    const b = store(file, clock);
    expect(b.get(one.token)).toBeNull();
    expect(b.get(two.token)).toBeNull();
    expect(b.get(three.token)).toBeNull();
    expect(rows(file)).toHaveLength(0);
  });

  it('a PIN elevation is not kept across a restart', () => {
    const file = folder();
    const clock = { t: 1_000_000 };
    const s = store(file, clock).create('otto', 'operator');
    s.elevation = { supervisor: 'sam', until: clock.t + 300_000 };
    const b = store(file, clock).get(s.token);
    expect(b && !('expired' in b) ? b.elevation : 'none').toBeNull();
  });

  it('a file that cannot be written leaves the sessions in memory (and says so)', () => {
    const errors: unknown[] = [];
    const broken = {
      load: () => {
        throw new Error('disk gone');
      },
      put: () => {
        throw new Error('disk gone');
      },
      remove: () => undefined,
      close: () => undefined,
    };
    const st = new SessionStore(
      IDLE,
      () => 1_000_000,
      broken,
      (e) => errors.push(e),
    );
    const s = st.create('otto', 'operator');
    expect(st.get(s.token)).not.toBeNull();
    expect(errors.length).toBeGreaterThan(0);
  });
});

describe('the gateway keeps sessions across a restart', () => {
  async function start(dir: string): Promise<string> {
    const gw = await startGateway({
      families: { prunt: testFamily('prunt') },
      env: {},
      machines: { file: null, machines: [] },
      dataDir: dir,
      usersFile: path.join(dir, 'users.json'),
    });
    cleanups.push(gw.close);
    return gw.url;
  }

  it('a cookie of before the restart still signs in; after logout it does not', async () => {
    const t = tempDir();
    cleanups.push(t.cleanup);
    writeJson(path.join(t.dir, 'users.json'), { users: [user('otto', 'operator', 'operator-pass-1')] });
    const first = await start(t.dir);
    const r = await consoleFetch(`${first}/api/login`, {
      method: 'POST',
      headers: { 'Content-Type': 'application/json' },
      body: JSON.stringify({ name: 'otto', password: 'operator-pass-1' }),
    });
    const cookie = (r.headers.getSetCookie()[0] ?? '').split(';')[0] ?? '';
    expect(r.status).toBe(200);
    await cleanups.pop()?.(); // the first server stops

    const second = await start(t.dir);
    const s = (await (await consoleFetch(`${second}/api/session`, { headers: { cookie } })).json()) as {
      user: { name: string } | null;
    };
    expect(s.user?.name).toBe('otto');
    await consoleFetch(`${second}/api/logout`, { method: 'POST', headers: { cookie } });
    await cleanups.pop()?.();

    const third = await start(t.dir);
    const after = (await (await consoleFetch(`${third}/api/session`, { headers: { cookie } })).json()) as {
      user: unknown;
    };
    expect(after.user).toBeNull();
  });
});
