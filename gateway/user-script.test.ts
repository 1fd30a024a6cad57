import { spawnSync } from 'node:child_process';
import path from 'node:path';
import { afterEach, describe, expect, it } from 'vitest';
import { main, UsageError } from '../scripts/user';
import { AuditLog } from './audit';
import { login, startGateway, tempDir, consoleFetch } from './test-util';
import { readUsers } from './users';

/** `npm run user`: the script writes the users file the gateway logs people in with. */

const cleanups: Array<() => Promise<void> | void> = [];
afterEach(async () => {
  for (const c of cleanups.splice(0).reverse()) await c();
});

const env = (dir: string): NodeJS.ProcessEnv => ({ SHOPDECK_DATA: dir, SHOPDECK_BCRYPT_COST: '4' });
const input = (...lines: string[]) => ({ line: (i: number) => Promise.resolve(lines[i] ?? '') });

describe('npm run user', () => {
  it('runs as a command reading the password from stdin', () => {
    const t = tempDir();
    cleanups.push(t.cleanup);
    const r = spawnSync(
      path.resolve('node_modules/.bin/tsx'),
      ['scripts/user.ts', 'add', 'ana', '--role', 'operator', '--password-stdin'],
      {
        input: 'ana-password-1\n',
        encoding: 'utf8',
        env: { ...process.env, SHOPDECK_USERS: '', ...env(t.dir) },
      },
    );
    expect(r.stderr).toBe('');
    expect(r.status).toBe(0);
    expect(r.stdout).toContain('access control is on');
    expect(readUsers(path.join(t.dir, 'users.json'))?.map((u) => [u.name, u.role])).toEqual([
      ['ana', 'operator'],
    ]);
  });

  it('adds users with bcrypt hashes, changes roles, audits, and the gateway uses them', async () => {
    const t = tempDir();
    cleanups.push(t.cleanup);
    const e = env(t.dir);
    await main(
      ['add', 'ana', '--role', 'operator', '--machines', 'laser-1,p1', '--password-stdin'],
      e,
      input('ana-password-1'),
    );
    await main(
      ['add', 'sam', '--role', 'supervisor', '--pin', '--password-stdin'],
      e,
      input('sam-password-1', '471147'),
    );
    const users = readUsers(path.join(t.dir, 'users.json'))!;
    expect(users.map((u) => [u.name, u.role, u.machines])).toEqual([
      ['ana', 'operator', ['laser-1', 'p1']],
      ['sam', 'supervisor', null],
    ]);
    expect(users[0]?.passwordHash).toMatch(/^\$2[aby]\$04\$/);
    expect(JSON.stringify(users)).not.toContain('ana-password-1');
    expect(users[1]?.pinHash).toMatch(/^\$2/);

    await expect(
      main(['add', 'bob', '--role', 'admin', '--password-stdin'], e, input('bob-password-1')),
    ).rejects.toThrow(UsageError);
    await expect(
      main(['add', 'bob', '--role', 'viewer', '--password-stdin'], e, input('short')),
    ).rejects.toThrow(/at least 8/);
    await expect(
      main(['add', 'sue', '--role', 'viewer', '--pin', '--password-stdin'], e, input('sue-password-1', '12')),
    ).rejects.toThrow(/6 to 12 digits/);
    await expect(
      main(['add', 'ana', '--role', 'viewer', '--password-stdin'], e, input('ana-password-2')),
    ).rejects.toThrow(/exists/);
    expect(await main(['role', 'ana', 'supervisor'], e)).toBe('ana: operator → supervisor');

    const audit = new AuditLog(t.dir).all();
    expect(audit.map((x) => [x.type, x.user, x.role, x.source])).toEqual([
      ['user-added', 'ana', 'operator', 'cli'],
      ['user-added', 'sam', 'supervisor', 'cli'],
      ['role-change', 'ana', 'supervisor', 'cli'],
    ]);

    const gw = await startGateway({
      machines: { file: null, machines: [] },
      families: {},
      dataDir: t.dir,
      env: {},
    });
    cleanups.push(gw.close);
    const cookie = await login(gw.url, 'ana', 'ana-password-1');
    const s = await (await consoleFetch(`${gw.url}/api/session`, { headers: { Cookie: cookie } })).json();
    expect(s).toMatchObject({
      mode: 'secured',
      user: { name: 'ana', role: 'supervisor', machines: ['laser-1', 'p1'] },
    });
    expect(await main(['list'], e)).toMatch(/ana\s+supervisor\s+laser-1,p1/);
    await main(['remove', 'ana'], e);
    // Removed: the session ends at once.
    expect((await consoleFetch(`${gw.url}/api/machines`, { headers: { Cookie: cookie } })).status).toBe(401);
  });
});
