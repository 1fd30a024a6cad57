import { statSync } from 'node:fs';
import path from 'node:path';
import { afterEach, describe, expect, it } from 'vitest';
import { createLogger } from '../server/log';
import { tempDir, user } from './test-util';
import { UserDirectory, writeUsers, type UserDirectoryOptions } from './users';

/**
 * The users file as the gateway sees it (issue 34: three `statSync` of it per proxied request):
 * looked at no more than once per interval, at once after a change the file system reports, so
 * an edit by `npm run user` (an atomic rename of the file) still takes effect promptly.
 */

const cleanups: Array<() => void> = [];
afterEach(() => {
  for (const c of cleanups.splice(0).reverse()) c();
});

const quiet = createLogger({ write: () => undefined });

function directory(opts: UserDirectoryOptions): { dir: UserDirectory; file: string; stats: () => number } {
  const t = tempDir();
  cleanups.push(t.cleanup);
  const file = path.join(t.dir, 'users.json');
  writeUsers(file, [user('ana', 'viewer', 'x')]);
  let stats = 0;
  const dir = new UserDirectory(file, quiet, {
    ...opts,
    stat: (f) => {
      stats++;
      return statSync(f);
    },
  });
  cleanups.push(() => dir.close());
  return { dir, file, stats: () => stats };
}

const sleep = (ms: number): Promise<void> => new Promise((r) => setTimeout(r, ms));

describe('the users file is looked at once per interval, not per request', () => {
  it('a thousand requests’ checks in one interval cost one stat; the next interval one more', () => {
    let now = 1_000_000;
    const { dir, stats } = directory({ watch: false, checkEveryMs: 1000, now: () => now });
    const atStart = stats();
    for (let i = 0; i < 1000; i++) {
      expect(dir.mode).toBe('secured');
      expect(dir.find('ana')?.role).toBe('viewer');
      void dir.generation;
    }
    expect(stats() - atStart).toBe(0);
    now += 999;
    dir.find('ana');
    expect(stats() - atStart).toBe(0);
    now += 1;
    for (let i = 0; i < 100; i++) dir.find('ana');
    expect(stats() - atStart).toBe(1);
  });

  it('without reports from the file system, an edit takes effect within the interval', () => {
    let now = 1_000_000;
    const { dir, file } = directory({ watch: false, checkEveryMs: 1000, now: () => now });
    expect(dir.find('bob')).toBeNull();
    const gen = dir.generation;
    writeUsers(file, [user('ana', 'viewer', 'x'), user('bob', 'operator', 'y')]);
    now += 1000;
    expect(dir.find('bob')?.role).toBe('operator');
    expect(dir.generation).toBe(gen + 1);
  });

  it('an edit the file system reports (the atomic rename of npm run user) takes effect at once, not after the interval', async () => {
    const { dir, file } = directory({ checkEveryMs: 3_600_000 });
    expect(dir.find('ana')?.role).toBe('viewer');
    writeUsers(file, [user('ana', 'supervisor', 'x')]);
    const end = Date.now() + 5000;
    while (dir.find('ana')?.role !== 'supervisor' && Date.now() < end) await sleep(10);
    expect(dir.find('ana')?.role).toBe('supervisor');
    // A removed user is gone as promptly (a session of theirs ends at the next request).
    writeUsers(file, []);
    while (dir.find('ana') !== null && Date.now() < end) await sleep(10);
    expect(dir.find('ana')).toBeNull();
    expect(dir.mode).toBe('secured');
  });
});
