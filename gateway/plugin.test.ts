import { mkdirSync, writeFileSync } from 'node:fs';
import type { AddressInfo } from 'node:net';
import path from 'node:path';
import { createServer, preview } from 'vite';
import { WebSocket } from 'ws';
import { afterEach, describe, expect, it } from 'vitest';
import { shopdeckGateway } from './plugin';
import { openWs, startStub, tempDir, writeJson, consoleFetch } from './test-util';

/** The plugin inside real Vite servers: dev (`vite`) and preview (`vite preview`). */

const cleanups: Array<() => Promise<void> | void> = [];
afterEach(async () => {
  for (const c of cleanups.splice(0).reverse()) await c();
});

function portOf(server: { address(): unknown } | null): number {
  return (server?.address() as AddressInfo).port;
}

describe('shopdeckGateway() in Vite', () => {
  it('refuses to start with a bad machines file, naming the file, the entry and the field', async () => {
    const t = tempDir();
    cleanups.push(t.cleanup);
    const file = writeJson(path.join(t.dir, 'machines.json'), {
      machines: [
        { id: 'ok-1', name: 'A', kind: 'xtool', url: 'http://10.0.0.1' },
        { id: 'cut', name: 'B', kind: 'laser', url: 'http://x' },
      ],
    });
    await expect(
      createServer({
        root: t.dir,
        configFile: false,
        logLevel: 'silent',
        plugins: [shopdeckGateway({ machinesFile: file, dataDir: t.dir, env: {} })],
      }),
    ).rejects.toThrow(/machines\.json[\s\S]*machines\[1\] \(id "cut"\): field "kind"/);
  });

  it('refuses to start with a broken users file', async () => {
    const t = tempDir();
    cleanups.push(t.cleanup);
    const usersFile = writeJson(path.join(t.dir, 'users.json'), {
      users: [{ name: 'ana', role: 'boss', passwordHash: 'x' }],
    });
    await expect(
      createServer({
        root: t.dir,
        configFile: false,
        logLevel: 'silent',
        plugins: [shopdeckGateway({ machinesFile: undefined, usersFile, dataDir: t.dir, env: {} })],
      }),
    ).rejects.toThrow(/users\.json is not valid: field "users\.0\.role"/);
  });

  it('serves /api and proxies /machines (HTTP and WebSocket) in dev, leaving Vite’s own socket alone', async () => {
    const t = tempDir();
    cleanups.push(t.cleanup);
    const stub = await startStub();
    cleanups.push(stub.close);
    const file = writeJson(path.join(t.dir, 'machines.json'), {
      machines: [{ id: 'laser-1', name: 'Laser 1', kind: 'xtool', url: stub.url, wsUrl: stub.wsUrl }],
    });
    writeFileSync(path.join(t.dir, 'index.html'), '<!doctype html><title>x</title>');
    const server = await createServer({
      root: t.dir,
      configFile: false,
      logLevel: 'silent',
      server: { host: '127.0.0.1', port: 0, strictPort: false },
      plugins: [shopdeckGateway({ machinesFile: file, dataDir: t.dir, env: {} })],
    });
    cleanups.push(() => server.close());
    await server.listen();
    const base = `http://127.0.0.1:${portOf(server.httpServer)}`;
    // The server's watch may have read the stub already (its `watch` then depends on when): the
    // rest is exact (no address, no secret).
    const list = (await (await consoleFetch(`${base}/api/machines`)).json()) as {
      machines: Array<Record<string, unknown>>;
    };
    expect({ ...list, machines: list.machines.map(({ watch: _seen, ...m }) => m) }).toEqual({
      machines: [{ id: 'laser-1', name: 'Laser 1', kind: 'xtool', simulated: false }],
      demo: false,
    });
    const r = await consoleFetch(`${base}/machines/laser-1/progress`);
    expect(await r.json()).toEqual({ ok: true, path: '/progress' });
    expect((await consoleFetch(`${base}/machines/laser-9/progress`)).status).toBe(404);
    const w = await openWs(`${base.replace('http', 'ws')}/machines/laser-1/`);
    expect(w.first).toBe('hello');
    await w.close();
    // Vite's HMR socket still works next to ours.
    const hmr = new WebSocket(base.replace('http', 'ws') + '/', 'vite-hmr');
    const opened = await new Promise<boolean>((resolve) => {
      hmr.once('open', () => resolve(true));
      hmr.once('error', () => resolve(false));
    });
    hmr.terminate();
    expect(opened).toBe(true);
    // The page itself is Vite's.
    expect((await consoleFetch(`${base}/`)).status).toBe(200);
  });

  it('works in vite preview (the served build)', async () => {
    const t = tempDir();
    cleanups.push(t.cleanup);
    const stub = await startStub();
    cleanups.push(stub.close);
    const file = writeJson(path.join(t.dir, 'machines.json'), {
      machines: [{ id: 'p1', name: 'Prunt', kind: 'prunt', url: stub.url }],
    });
    mkdirSync(path.join(t.dir, 'dist'));
    writeFileSync(path.join(t.dir, 'dist', 'index.html'), '<!doctype html><title>built</title>');
    const server = await preview({
      root: t.dir,
      configFile: false,
      logLevel: 'silent',
      preview: { host: '127.0.0.1', port: 0, strictPort: false },
      plugins: [shopdeckGateway({ machinesFile: file, dataDir: t.dir, env: {} })],
    });
    cleanups.push(() => server.close());
    const base = `http://127.0.0.1:${portOf(server.httpServer)}`;
    const r = await consoleFetch(`${base}/machines/p1/status`, {
      method: 'POST',
      body: '{}',
      headers: { 'X-Shopdeck-Command': 'prunt.x' },
    });
    expect(r.status).toBe(200);
    expect(stub.seen[0]).toMatchObject({ method: 'POST', url: '/status' });
    const session = await (await consoleFetch(`${base}/api/session`)).json();
    expect(session).toMatchObject({ mode: 'open' });
    expect(await (await consoleFetch(`${base}/`)).text()).toContain('built');
  });

  it('preview: security headers on every page, no source maps, no CORS for other localhost origins', async () => {
    const t = tempDir();
    cleanups.push(t.cleanup);
    mkdirSync(path.join(t.dir, 'dist', 'assets'), { recursive: true });
    writeFileSync(path.join(t.dir, 'dist', 'index.html'), '<!doctype html><title>built</title>');
    writeFileSync(path.join(t.dir, 'dist', 'assets', 'app.js'), 'export {}');
    writeFileSync(path.join(t.dir, 'dist', 'assets', 'app.js.map'), '{"sources":["secret.ts"]}');
    const server = await preview({
      root: t.dir,
      configFile: false,
      logLevel: 'silent',
      preview: { host: '127.0.0.1', port: 0, strictPort: false },
      plugins: [shopdeckGateway({ dataDir: t.dir, env: {} })],
    });
    cleanups.push(() => server.close());
    const base = `http://127.0.0.1:${portOf(server.httpServer)}`;
    for (const p of ['/', '/m/some-machine', '/assets/app.js']) {
      const r = await fetch(`${base}${p}`);
      const csp = r.headers.get('content-security-policy') ?? '';
      expect(csp, p).toContain("frame-ancestors 'none'");
      expect(csp, p).toMatch(/script-src 'self'(;|$)/);
      expect(csp, p).not.toContain('unsafe-eval');
      expect(r.headers.get('x-frame-options'), p).toBe('DENY');
      expect(r.headers.get('x-content-type-options'), p).toBe('nosniff');
      expect(r.headers.get('referrer-policy'), p).toBe('no-referrer');
    }
    expect((await fetch(`${base}/assets/app.js.map`)).status).toBe(404);
    // A page on another localhost port asks for CORS: no allow-origin comes back.
    const pre = await fetch(`${base}/api/session`, {
      method: 'OPTIONS',
      headers: {
        Origin: 'http://localhost:9999',
        'Access-Control-Request-Method': 'POST',
        'Access-Control-Request-Headers': 'x-shopdeck',
      },
    });
    expect(pre.headers.get('access-control-allow-origin')).toBeNull();
    const get = await fetch(`${base}/`, { headers: { Origin: 'http://localhost:9999' } });
    expect(get.headers.get('access-control-allow-origin')).toBeNull();
  });
});
