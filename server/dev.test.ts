import { spawn } from 'node:child_process';
import { readFileSync } from 'node:fs';
import path from 'node:path';
import { afterEach, describe, expect, it } from 'vitest';

/**
 * `npm run dev` keeps Vite with the same gateway plugin. Run the script exactly as package.json
 * says (through npm), on a free port, and check the page, the gateway and the demo fleet's
 * simulators (which load data lazily, after Vite has loaded its config) all keep working.
 */

const root = path.resolve(import.meta.dirname, '..');
const pkg = JSON.parse(readFileSync(path.join(root, 'package.json'), 'utf8')) as {
  scripts: Record<string, string>;
};

const children: ReturnType<typeof spawn>[] = [];
afterEach(() => {
  // npm runs the script in a shell: end the whole process group, not only npm.
  for (const c of children) if (c.pid) process.kill(-c.pid, 'SIGKILL');
  children.length = 0;
});

describe('npm run dev', () => {
  it('serves the page and the gateway with the demo fleet, and stays up while the simulators run', async () => {
    expect(pkg.scripts.dev).toBeDefined();
    const port = 40000 + Math.floor(Math.random() * 20000);
    const env: NodeJS.ProcessEnv = {};
    for (const [k, v] of Object.entries(process.env)) if (!k.startsWith('SHOPDECK_')) env[k] = v;
    const child = spawn('npm', ['run', 'dev', '--', '--port', String(port), '--strictPort'], {
      cwd: root,
      env,
      stdio: ['ignore', 'pipe', 'pipe'],
      detached: true,
    });
    children.push(child);
    let output = '';
    child.stdout.on('data', (d: Buffer) => (output += d.toString()));
    child.stderr.on('data', (d: Buffer) => (output += d.toString()));
    let exited = false;
    child.once('exit', () => (exited = true));

    const base = `http://localhost:${port}`;
    const deadline = Date.now() + 40_000;
    let page: Response | undefined;
    while (!exited && Date.now() < deadline) {
      page = await fetch(`${base}/`).catch(() => undefined);
      if (page) break;
      await new Promise((r) => setTimeout(r, 250));
    }
    expect(page?.status, output).toBe(200);
    expect(await page?.text()).toContain('<div id="root">');

    const machines = await fetch(`${base}/api/machines`, { headers: { 'X-Shopdeck': '1' } });
    expect(machines.status).toBe(200);
    const body = (await machines.json()) as { machines: { id: string; kind: string }[] };
    // Every family, and the Duet twice: with DSF and standalone (rr_*).
    expect(body.machines.map((m) => m.kind).sort()).toEqual([
      'duet',
      'duet',
      'g2core',
      'prunt',
      'touchcut',
      'xtool',
    ]);

    // The simulators start their demo jobs after start-up, loading their data then: a dev server
    // whose module loader has closed dies here.
    const prunt = body.machines.find((m) => m.kind === 'prunt');
    await new Promise((r) => setTimeout(r, 3000));
    const status = await fetch(`${base}/api/m/${prunt?.id ?? ''}/websocket/everything`, {
      headers: { 'X-Shopdeck': '1' },
    }).catch(() => undefined);
    expect(exited, output).toBe(false);
    expect(status).toBeDefined();
  }, 60_000);
});
