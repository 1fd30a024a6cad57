import { spawn, spawnSync } from 'node:child_process';
import { existsSync, readFileSync, utimesSync, writeFileSync } from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { afterEach, describe, expect, it } from 'vitest';
import { tempDir } from './test-util';
import { readUsers, updateUsers, UsersFileLockedError, withFileLock, type UserRecord } from './users';

/**
 * Finding 18: three concurrent `npm run user -- add` each printed "added" and the file kept one.
 * Every change of the users file is a locked read-modify-write (an O_EXCL lock file beside it)
 * with an atomic rename: no edit is lost, whatever runs at the same time.
 */

const cleanups: Array<() => void> = [];
afterEach(() => {
  for (const c of cleanups.splice(0).reverse()) c();
});

const tsx = path.resolve('node_modules/.bin/tsx');

function folder(): string {
  const t = tempDir();
  cleanups.push(t.cleanup);
  return t.dir;
}

/** `tsx scripts/user.ts …` as a real process; resolves with its exit code and output. */
function userScript(
  dir: string,
  args: string[],
  stdin: string,
): Promise<{ code: number | null; stdout: string; stderr: string }> {
  return new Promise((resolve, reject) => {
    const child = spawn(tsx, ['scripts/user.ts', ...args], {
      env: { ...process.env, SHOPDECK_USERS: '', SHOPDECK_DATA: dir, SHOPDECK_BCRYPT_COST: '4' },
      stdio: ['pipe', 'pipe', 'pipe'],
    });
    let stdout = '';
    let stderr = '';
    child.stdout.on('data', (d: Buffer) => (stdout += d.toString()));
    child.stderr.on('data', (d: Buffer) => (stderr += d.toString()));
    child.on('error', reject);
    child.on('exit', (code) => resolve({ code, stdout, stderr }));
    child.stdin.end(stdin);
  });
}

const record = (name: string): UserRecord => ({
  name,
  role: 'viewer',
  machines: null,
  passwordHash: '$2b$04$abcdefghijklmnopqrstuuJq7v7C1b3m0m3J1Yk5lR5V8nYpQ2Wm',
  pinHash: null,
});

describe('18: concurrent edits of the users file are never lost', () => {
  it('six concurrent `npm run user -- add` processes: every user is in the file', async () => {
    const dir = folder();
    const names = Array.from({ length: 6 }, (_, i) => `user${i}`);
    const runs = await Promise.all(
      names.map((n) =>
        userScript(dir, ['add', n, '--role', 'viewer', '--password-stdin'], `${n}-password-1\n`),
      ),
    );
    for (const [i, r] of runs.entries()) {
      expect(r.stderr, names[i]).toBe('');
      expect(r.code, names[i]).toBe(0);
      expect(r.stdout, names[i]).toContain(`added ${names[i]}`);
    }
    const file = path.join(dir, 'users.json');
    expect(
      readUsers(file)
        ?.map((u) => u.name)
        .sort(),
    ).toEqual(names);
    expect(existsSync(`${file}.lock`)).toBe(false);
    // Mixed with changes of existing users at the same time: all of them land too.
    const more = await Promise.all([
      userScript(dir, ['role', 'user0', 'operator'], ''),
      userScript(dir, ['add', 'late', '--role', 'supervisor', '--password-stdin'], 'late-password-1\n'),
      userScript(dir, ['remove', 'user1'], ''),
      userScript(dir, ['machines', 'user2', 'demo-xtool'], ''),
    ]);
    for (const r of more) expect(r.code, r.stderr).toBe(0);
    const after = readUsers(file) ?? [];
    expect(after.map((u) => u.name).sort()).toEqual([...names.filter((n) => n !== 'user1'), 'late'].sort());
    expect(after.find((u) => u.name === 'user0')?.role).toBe('operator');
    expect(after.find((u) => u.name === 'user2')?.machines).toEqual(['demo-xtool']);
    // Real processes on a shared machine: generous, and not what the test measures.
  }, 240_000);

  it('a lock left by a process that died is broken; the add goes through', async () => {
    const dir = folder();
    const dead = spawnSync(process.execPath, ['-e', 'process.stdout.write(String(process.pid))'], {
      encoding: 'utf8',
    });
    const deadPid = Number(dead.stdout);
    expect(deadPid).toBeGreaterThan(0);
    const file = path.join(dir, 'users.json');
    writeFileSync(
      `${file}.lock`,
      JSON.stringify({ pid: deadPid, host: os.hostname(), at: new Date().toISOString(), nonce: 'x' }),
    );
    const r = await userScript(
      dir,
      ['add', 'ana', '--role', 'viewer', '--password-stdin'],
      'ana-password-1\n',
    );
    expect(r.stderr).toBe('');
    expect(r.code).toBe(0);
    expect(readUsers(file)?.map((u) => u.name)).toEqual(['ana']);
    expect(existsSync(`${file}.lock`)).toBe(false);
  }, 60_000);
});

describe('withFileLock', () => {
  it('waits for a live holder and gives up with a clear error, touching nothing', async () => {
    const dir = folder();
    const file = path.join(dir, 'users.json');
    const lock = `${file}.lock`;
    // A live holder: this very process, just now.
    const held = JSON.stringify({
      pid: process.pid,
      host: os.hostname(),
      at: new Date().toISOString(),
      nonce: 'held',
    });
    writeFileSync(lock, held);
    let ran = false;
    const err = await withFileLock(file, () => (ran = true), { timeoutMs: 150, retryMs: 10 }).catch(
      (e: unknown) => e,
    );
    expect(err).toBeInstanceOf(UsersFileLockedError);
    expect(String(err)).toContain(lock);
    expect(ran).toBe(false);
    expect(readFileSync(lock, 'utf8')).toBe(held);
  });

  it('breaks a lock older than the stale age even from a live or foreign holder, and an empty one', async () => {
    const dir = folder();
    const file = path.join(dir, 'users.json');
    const lock = `${file}.lock`;
    const old = new Date(Date.now() - 120_000);
    writeFileSync(lock, JSON.stringify({ pid: 1, host: 'another-pc', at: old.toISOString(), nonce: 'old' }));
    utimesSync(lock, old, old);
    expect(await withFileLock(file, () => 'ran', { timeoutMs: 1000, retryMs: 10, staleMs: 60_000 })).toBe(
      'ran',
    );
    writeFileSync(lock, '');
    utimesSync(lock, old, old);
    expect(await withFileLock(file, () => 'again', { timeoutMs: 1000, retryMs: 10 })).toBe('again');
    expect(existsSync(lock)).toBe(false);
  });

  it('in one process too: concurrent updateUsers calls all land, and a refused change writes nothing', async () => {
    const dir = folder();
    const file = path.join(dir, 'users.json');
    await Promise.all(
      Array.from({ length: 10 }, (_, i) =>
        updateUsers(file, async (users) => {
          await new Promise((r) => setTimeout(r, 1));
          return [...users, record(`u${i}`)];
        }),
      ),
    );
    expect(readUsers(file)?.length).toBe(10);
    const before = readFileSync(file, 'utf8');
    await expect(
      updateUsers(file, () => {
        throw new Error('refused');
      }),
    ).rejects.toThrow('refused');
    expect(readFileSync(file, 'utf8')).toBe(before);
    expect(existsSync(`${file}.lock`)).toBe(false);
  });
});
