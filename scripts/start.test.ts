import { spawn } from 'node:child_process';
import { mkdtempSync, rmSync, writeFileSync } from 'node:fs';
import { tmpdir } from 'node:os';
import path from 'node:path';
import { afterEach, describe, expect, it } from 'vitest';
import { buildSummary, sqliteLine } from './start-output.mjs';

/** `npm start` on a fresh machine: a few lines, the URL to open last. */

/** What `npm run build` printed (shortened: ~110 lines in a real build). */
const BUILD_OUTPUT = `vite v8.3.8 building client environment for production...
transforming...
✓ 350 modules transformed.
rendering chunks...
computing gzip size...
dist/index.html                                   2.10 kB │ gzip:  0.90 kB
dist/assets/errors-Drbjq_Ly.js                     1.50 kB │ gzip:  0.77 kB
✓ built in 1.34s

PWA v2.0.0
mode      generateSW
precache  115 entries (868.56 KiB)
files generated
  dist/sw.js
shopdeck: precompressed /work/dist: 170 written, 0 up to date (875.3 KiB → br 270.4 KiB, gzip 305.8 KiB)
`;

describe('npm start output', () => {
  it('sums the build up in one line', () => {
    const line = buildSummary(BUILD_OUTPUT, 11_694);
    expect(line).toBe('Built the console in 12 s (350 modules; 115 files, 868.56 KiB).');
    expect(line).not.toContain('\n');
    expect(buildSummary('', 2_345)).toBe('Built the console in 2.3 s.');
  });

  it('says in one line whether the SQLite module loads, and what to do when it does not', () => {
    expect(sqliteLine(() => ({ version: '12.11.1' }))).toEqual({
      ok: true,
      line: 'SQLite module loads (better-sqlite3 12.11.1).',
    });
    const bad = sqliteLine(() => {
      throw new Error('Could not locate the bindings file. Tried:\n → /x/build/better_sqlite3.node');
    });
    expect(bad.ok).toBe(false);
    expect(bad.line).toMatch(
      /^The SQLite module \(better-sqlite3\) does not load: Could not locate the bindings file\. Tried:\. Run `npm rebuild better-sqlite3`/,
    );
    expect(bad.line).not.toContain('\n');
  });
});

describe('npm start (the real script)', () => {
  const dirs: string[] = [];
  afterEach(() => {
    for (const d of dirs.splice(0)) rmSync(d, { recursive: true, force: true });
  });

  it('prints the SQLite line, then the banner, whose last line is the URL', async () => {
    const dir = mkdtempSync(path.join(tmpdir(), 'shopdeck-start-'));
    dirs.push(dir);
    // No machines: nothing is logged after the banner (the watch reports what machines do).
    const machines = path.join(dir, 'machines.json');
    writeFileSync(machines, '{ "machines": [] }');
    const child = spawn(process.execPath, ['scripts/start.mjs'], {
      env: {
        ...process.env,
        SHOPDECK_PORT: '0',
        SHOPDECK_DATA: dir,
        SHOPDECK_MACHINES: machines,
        SHOPDECK_USERS: '',
        SHOPDECK_LOG: '',
      },
      stdio: ['ignore', 'pipe', 'pipe'],
    });
    let out = '';
    let err = '';
    child.stdout.on('data', (b: Buffer) => (out += b.toString('utf8')));
    child.stderr.on('data', (b: Buffer) => (err += b.toString('utf8')));
    try {
      // The build (when dist/ is older than the sources) takes a while on a slow machine.
      const end = Date.now() + 150_000;
      while (!/➜ http:\/\/\S+\n/.test(out) && Date.now() < end && child.exitCode === null)
        await new Promise((r) => setTimeout(r, 100));
      // Anything printed right after the banner would show here.
      await new Promise((r) => setTimeout(r, 1500));
    } finally {
      child.kill('SIGTERM');
      await new Promise((r) => child.once('exit', r));
    }
    const lines = out.split('\n').filter((l) => l.trim() !== '');
    const stop = lines.findIndex((l) => /stopping/.test(l));
    const shown = stop < 0 ? lines : lines.slice(0, stop);
    expect(err, err).toBe('');
    expect(shown.at(-1)).toMatch(/^ {2}➜ http:\/\/localhost:\d+\/$/);
    expect(shown).toContain('Open the console at:');
    expect(shown.some((l) => /^SQLite module loads \(better-sqlite3 \d+\.\d+\.\d+\)\.$/.test(l))).toBe(true);
    // At most one line for a build, and no build output.
    expect(shown.filter((l) => l.startsWith('Built the console')).length).toBeLessThanOrEqual(1);
    expect(shown.some((l) => /modules transformed|precache|dist\/assets\//.test(l))).toBe(false);
    expect(shown.length).toBeLessThanOrEqual(10);
  }, 180_000);
});
