import { mkdtempSync, readdirSync, readFileSync, rmSync } from 'node:fs';
import http from 'node:http';
import os from 'node:os';
import path from 'node:path';
import { build } from 'vite';
import { afterAll, beforeAll, describe, expect, it } from 'vitest';
import type { BundleReport } from '../scripts/bundle-report';
import { MACHINE_KINDS } from '../src/controllers';
import { NEVER_CACHED } from '../src/app/pwa/options';
import { compressDist } from './compress';
import { createLogger } from './log';
import { createShopdeckServer, IMMUTABLE, type ShopdeckServer } from './server';

/**
 * The installable console as the server sends it: a real build (vite.config.ts with
 * vite-plugin-pwa) in a temporary folder, served by Shopdeck's server. The service worker and
 * the manifest are never cached by the browser's HTTP cache (so an update is seen), the page's
 * CSP lets them work, and the worker precaches the app shell and nothing of /api or /machines.
 */

const work = mkdtempSync(path.join(os.tmpdir(), 'shopdeck-pwa-'));
const dist = path.join(work, 'dist');
let server: ShopdeckServer;
let base = '';

beforeAll(async () => {
  await build({ logLevel: 'silent', build: { outDir: dist, emptyOutDir: true } });
  await compressDist(dist);
  server = createShopdeckServer({
    distDir: dist,
    host: '127.0.0.1',
    port: 0,
    env: {},
    dataDir: path.join(work, 'data'),
    logger: createLogger({ write: () => undefined }),
  });
  const info = await server.listen();
  base = `http://127.0.0.1:${info.port}`;
}, 180_000);

afterAll(async () => {
  await server?.close();
  rmSync(work, { recursive: true, force: true });
});

interface Answer {
  status: number;
  headers: { get(name: string): string | null };
  body: Buffer;
  text(): Promise<string>;
  json(): Promise<unknown>;
  arrayBuffer(): Promise<Uint8Array>;
}

/** A GET that sends only the headers given (fetch would add Accept-Encoding and decode). */
const get = (p: string, headers: Record<string, string> = {}): Promise<Answer> =>
  new Promise((resolve, reject) => {
    http
      .get(`${base}${p}`, { headers }, (res) => {
        const parts: Buffer[] = [];
        res.on('data', (c: Buffer) => parts.push(c));
        res.on('end', () => {
          const body = Buffer.concat(parts);
          resolve({
            status: res.statusCode ?? 0,
            headers: {
              get: (name) => {
                const v = res.headers[name.toLowerCase()];
                return v === undefined ? null : String(v);
              },
            },
            body,
            text: () => Promise.resolve(body.toString('utf8')),
            json: () => Promise.resolve(JSON.parse(body.toString('utf8')) as unknown),
            arrayBuffer: () => Promise.resolve(new Uint8Array(body)),
          });
        });
      })
      .on('error', reject);
  });

/** A PNG's width and height from its IHDR chunk. */
function pngSize(b: Uint8Array): [number, number] {
  const v = new DataView(b.buffer, b.byteOffset, b.byteLength);
  expect([...b.slice(1, 4)].map((c) => String.fromCharCode(c)).join('')).toBe('PNG');
  return [v.getUint32(16), v.getUint32(20)];
}

describe('the installable console (vite-plugin-pwa build, Shopdeck server)', () => {
  it('serves sw.js and the manifest with no-cache, hashed assets immutable', async () => {
    for (const enc of ['', 'br', 'gzip']) {
      const sw = await get('/sw.js', enc ? { 'Accept-Encoding': enc } : {});
      expect(sw.status, enc).toBe(200);
      expect(sw.headers.get('cache-control'), enc).toBe('no-cache');
      expect(sw.headers.get('content-type'), enc).toMatch(/javascript/);
      expect(sw.headers.get('content-encoding') ?? '', enc).toBe(enc);
    }
    const manifest = await get('/manifest.webmanifest');
    expect(manifest.status).toBe(200);
    expect(manifest.headers.get('cache-control')).toBe('no-cache');
    expect(manifest.headers.get('content-type')).toMatch(/^application\/manifest\+json/);
    const asset = readdirSync(path.join(dist, 'assets')).find((f) => f.endsWith('.js'));
    const a = await get(`/assets/${asset}`);
    expect(a.status).toBe(200);
    expect(a.headers.get('cache-control')).toBe(IMMUTABLE);
  });

  it('lets the page register the worker and read the manifest (CSP), and links both', async () => {
    const page = await get('/m/laser-1');
    expect(page.headers.get('cache-control')).toBe('no-cache');
    const csp = (page.headers.get('content-security-policy') ?? '').split(';').map((d) => d.trim());
    expect(csp).toContain("worker-src 'self'");
    expect(csp).toContain("manifest-src 'self'");
    expect(csp).toContain("script-src 'self'");
    const html = await page.text();
    expect(html).toContain('<link rel="manifest" href="/manifest.webmanifest">');
    expect(html).toMatch(/<meta name="theme-color" content="#ffffff"/);
    // Registered by the page's own code (a chunk), not an inline script the CSP would refuse.
    expect(html).not.toMatch(/<script>|registerSW\.js/);
  });

  it('has a valid manifest whose icons are there, at their sizes', async () => {
    const m = (await (await get('/manifest.webmanifest')).json()) as {
      name: string;
      short_name: string;
      start_url: string;
      display: string;
      theme_color: string;
      background_color: string;
      icons: Array<{ src: string; sizes: string; type: string; purpose?: string }>;
    };
    expect(m).toMatchObject({
      name: 'Shopdeck',
      short_name: 'Shopdeck',
      start_url: '/',
      display: 'standalone',
    });
    expect(m.theme_color).toMatch(/^#[0-9a-f]{6}$/);
    expect(m.background_color).toMatch(/^#[0-9a-f]{6}$/);
    expect(m.icons.map((i) => `${i.sizes} ${i.purpose ?? 'any'}`).sort()).toEqual([
      '192x192 any',
      '512x512 any',
      '512x512 maskable',
    ]);
    for (const icon of [
      ...m.icons,
      { src: '/icons/apple-touch-icon.png', sizes: '180x180', type: 'image/png' },
    ]) {
      const r = await get(icon.src);
      expect(r.status, icon.src).toBe(200);
      expect(r.headers.get('content-type'), icon.src).toBe('image/png');
      const [w, h] = pngSize(new Uint8Array(await r.arrayBuffer()));
      expect(`${w}x${h}`, icon.src).toBe(icon.sizes);
    }
  });

  it('precaches index.html and every JS and CSS chunk (each family’s code), nothing of /api or /machines', async () => {
    const sw = await (await get('/sw.js')).text();
    const urls = [...sw.matchAll(/\{\s*"?url"?:\s*"([^"]+)",\s*"?revision"?:\s*(?:"[^"]*"|null)\s*\}/g)].map(
      (m) => m[1] ?? '',
    );
    expect(urls).toContain('index.html');
    expect(urls).toContain('manifest.webmanifest');
    const assets = readdirSync(path.join(dist, 'assets')).filter((f) => /\.(js|css)$/.test(f));
    expect(assets.length).toBeGreaterThan(10);
    for (const f of assets) expect(urls, f).toContain(`assets/${f}`);
    const report = JSON.parse(
      readFileSync(path.join(work, 'bundle-report', 'bundle.json'), 'utf8'),
    ) as BundleReport;
    for (const kind of MACHINE_KINDS) {
      const family = report.chunks.find((c) => c.facade === `src/controllers/${kind}/module.tsx`);
      expect(family, kind).toBeDefined();
      expect(urls, kind).toContain(family?.file);
    }
    expect(urls.filter((u) => /^\/?(api|machines)\b/.test(u) || /\.(br|gz|map)$/.test(u))).toEqual([]);
    expect(new Set(urls).size).toBe(urls.length);
  });

  it('answers navigations with the shell except /api, /machines, /healthz and the CA, and caches nothing at run time', async () => {
    const sw = await (await get('/sw.js')).text();
    const denylist = /denylist:\[([^\]]*(?:\][^\]]*)*?)\]\}/.exec(sw)?.[1] ?? '';
    for (const r of NEVER_CACHED) expect(denylist, String(r)).toContain(String(r));
    expect(sw).toContain('createHandlerBoundToURL');
    // No runtime caching strategy (options.test.ts checks the configuration, pwa.spec.ts the caches).
    expect(sw).not.toMatch(/NetworkFirst|CacheFirst|StaleWhileRevalidate|NetworkOnly|networkTimeoutSeconds/);
    // The workbox runtime is inlined: no second file to keep fresh.
    expect(sw).not.toMatch(/importScripts/);
    expect(readdirSync(dist).filter((f) => /^workbox-.*\.js$/.test(f))).toEqual([]);
  });
});
