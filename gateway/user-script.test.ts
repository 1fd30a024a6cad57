import { spawnSync } from 'node:child_process';
import { writeFileSync } from 'node:fs';
import os from 'node:os';
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
/** A machines file with `ids` (simulated xTools), named by SHOPDECK_MACHINES in the env returned. */
function withMachines(dir: string, ids: string[]): NodeJS.ProcessEnv {
  const file = path.join(dir, 'machines.json');
  writeFileSync(
    file,
    JSON.stringify({ machines: ids.map((id) => ({ id, name: id, kind: 'xtool', simulated: true })) }),
  );
  return { ...env(dir), SHOPDECK_MACHINES: file };
}
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
    const e = withMachines(t.dir, ['laser-1', 'p1']);
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

    // Who: the OS user who ran the script, not the user added; the user changed is in the detail.
    const audit = new AuditLog(t.dir).all();
    const me = os.userInfo().username;
    expect(audit.map((x) => [x.type, x.user, x.role, x.source, x.detail])).toEqual([
      ['user-added', me, 'operator', 'cli', 'ana as operator for laser-1, p1'],
      ['user-added', me, 'supervisor', 'cli', 'sam as supervisor'],
      ['role-change', me, 'supervisor', 'cli', 'ana: operator → supervisor'],
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

  it('refuses a machine id the machines file lacks, naming the known ones, before asking a password', async () => {
    const t = tempDir();
    cleanups.push(t.cleanup);
    const asked: string[] = [];
    const io = {
      line: () => Promise.resolve('ana-password-1'),
      ask: (p: string) => {
        asked.push(p);
        return Promise.resolve('ana-password-1');
      },
    };
    // The demo fleet (no machines file): the README's old example ids are not in it.
    const demo = { ...env(t.dir), SHOPDECK_MACHINES: '' };
    const cwd = process.cwd();
    process.chdir(t.dir);
    try {
      await expect(
        main(['add', 'bob', '--role', 'operator', '--machines', 'laser-1,demo-xtool'], demo, io),
      ).rejects.toThrow(/no machine "laser-1" in the built-in demo fleet.*demo-xtool, .*demo-touchcut/);
    } finally {
      process.chdir(cwd);
    }
    expect(asked).toEqual([]);
    const e = withMachines(t.dir, ['laser-1', 'p1']);
    await expect(
      main(['add', 'bob', '--role', 'operator', '--machines', 'laser-1,plasma-9', '--password-stdin'], e, io),
    ).rejects.toThrow(/no machine "plasma-9" in .*machines\.json; its machines are laser-1, p1/);
    expect(readUsers(path.join(t.dir, 'users.json'))).toBeNull();
    await main(['add', 'bob', '--role', 'operator', '--machines', 'p1', '--password-stdin'], e, io);
    await expect(main(['machines', 'bob', 'p1,p9'], e, io)).rejects.toThrow(/no machine "p9"/);
    expect(await main(['machines', 'bob', 'laser-1'], e, io)).toBe('bob: machines laser-1');
  });

  it('asks again on the terminal after a short or mistyped password, and gives up after three tries', async () => {
    const t = tempDir();
    cleanups.push(t.cleanup);
    const e = env(t.dir);
    const answers = ['short', 'long-enough-1', 'long-enough-2', 'long-enough-1', 'long-enough-1'];
    const asked: string[] = [];
    const said: string[] = [];
    const io = {
      line: () => Promise.reject(new Error('not piped')),
      ask: (p: string) => {
        asked.push(p);
        return Promise.resolve(answers.shift() ?? '');
      },
      say: (s: string) => said.push(s),
    };
    expect(await main(['add', 'cy', '--role', 'viewer'], e, io)).toContain('added cy (viewer)');
    expect(asked).toEqual(['password: ', 'password: ', 'password again: ', 'password: ', 'password again: ']);
    expect(said).toEqual([
      'the password must have at least 8 characters: try again',
      'the two passwords differ: try again',
    ]);
    const written = readUsers(path.join(t.dir, 'users.json'));
    expect(written?.map((u) => u.name)).toEqual(['cy']);

    const short = { ...io, ask: () => Promise.resolve('short'), say: () => undefined };
    await expect(main(['add', 'di', '--role', 'viewer'], e, short)).rejects.toThrow(/at least 8/);
  });
});
