import { spawn, spawnSync } from 'node:child_process';
import { cpSync, mkdirSync, mkdtempSync, rmSync, writeFileSync } from 'node:fs';
import { tmpdir } from 'node:os';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import { afterAll, describe, expect, it } from 'vitest';

/**
 * Issue 13: what the server needs at run time is in `dependencies`. A copy of the project with a
 * prebuilt `dist/` and only the production dependencies (`npm ci --omit=dev`) starts with
 * `npm start` and answers `/`. (It installs from the npm cache or registry: slow, so it runs once.)
 */
const root = fileURLToPath(new URL('..', import.meta.url));
const work = mkdtempSync(path.join(tmpdir(), 'shopdeck-omit-dev-'));

afterAll(() => rmSync(work, { recursive: true, force: true }));

describe('npm ci --omit=dev && npm start on a built tree', { timeout: 240_000 }, () => {
  it('installs no build tools and serves the console', async () => {
    for (const f of ['package.json', 'package-lock.json', 'index.html', 'tsconfig.json'])
      cpSync(path.join(root, f), path.join(work, f));
    for (const d of ['server', 'gateway', 'src', 'scripts', 'public'])
      cpSync(path.join(root, d), path.join(work, d), {
        recursive: true,
        filter: (p) => !p.endsWith('.test.ts'),
      });
    const install = spawnSync(
      'npm',
      ['ci', '--omit=dev', '--ignore-scripts', '--prefer-offline', '--no-audit', '--no-fund'],
      {
        cwd: work,
        encoding: 'utf8',
      },
    );
    expect(install.status, install.stderr).toBe(0);
    // No build tools came with it.
    expect(spawnSync('node', ['-e', "require.resolve('vite')"], { cwd: work }).status).not.toBe(0);
    // A prebuilt dist/, newer than the sources (written last).
    mkdirSync(path.join(work, 'dist', 'assets'), { recursive: true });
    writeFileSync(path.join(work, 'dist', 'assets', 'app-abc123.js'), 'console.log("shopdeck")');
    writeFileSync(
      path.join(work, 'dist', 'index.html'),
      '<!doctype html><title>Shopdeck</title><script type="module" src="/assets/app-abc123.js"></script>',
    );
    const child = spawn('npm', ['start', '--', '--port', '0', '--host', '127.0.0.1'], {
      cwd: work,
      env: {
        ...process.env,
        SHOPDECK_DATA: path.join(work, 'data'),
        SHOPDECK_MACHINES: '',
        SHOPDECK_LOG: '',
      },
      stdio: ['ignore', 'pipe', 'pipe'],
    });
    try {
      let out = '';
      const url = await new Promise<string>((resolve, reject) => {
        const timer = setTimeout(() => reject(new Error(`no URL printed:\n${out}`)), 60_000);
        const onData = (d: Buffer) => {
          out += d.toString();
          const m = /http:\/\/[^\s/]+:\d+\//.exec(out);
          if (m) {
            clearTimeout(timer);
            resolve(m[0]);
          }
        };
        child.stdout.on('data', onData);
        child.stderr.on('data', onData);
        child.on('exit', (code) => reject(new Error(`exited ${code}:\n${out}`)));
      });
      const res = await fetch(url);
      expect(res.status).toBe(200);
      expect(await res.text()).toContain('<title>Shopdeck</title>');
      const health = (await (await fetch(`${url}healthz`)).json()) as { ok: boolean };
      expect(health.ok).toBe(true);
    } finally {
      child.kill('SIGTERM');
    }
  });
});
