import { expect, test, type Page } from '@playwright/test';
import { resetSimulators } from './simulators';

/**
 * The installable console (issue 17): the manifest, the service worker that controls the page
 * on 127.0.0.1 (a secure context), the offline app shell that says "Console unreachable" and
 * recovers by itself, and nothing of /api or /machines ever answered from a cache.
 */

const API = '/api/machines';
const MACHINE = '/machines/demo-xtool/peripherystatus';

/** Two reads the way the page makes them (the gateway wants its console header). */
function readBoth(page: Page): Promise<string[]> {
  return page.evaluate(
    (urls) =>
      Promise.all(
        urls.map((u) =>
          fetch(u, { headers: { 'X-Shopdeck-Console': '1' } }).then(
            (r) => `HTTP ${r.status}`,
            (e: unknown) => `failed: ${e instanceof Error ? e.name : String(e)}`,
          ),
        ),
      ),
    [API, MACHINE],
  );
}

/** Every URL in the page's caches (Cache Storage). */
function cachedUrls(page: Page): Promise<string[]> {
  return page.evaluate(async () => {
    const out: string[] = [];
    for (const name of await caches.keys())
      for (const req of await (await caches.open(name)).keys()) out.push(new URL(req.url).pathname);
    return out;
  });
}

/** Waits until the service worker is active and controls the page. */
async function controlled(page: Page): Promise<string> {
  await page.evaluate(() => navigator.serviceWorker.ready.then(() => undefined));
  await expect
    .poll(() => page.evaluate(() => navigator.serviceWorker.controller?.scriptURL ?? null))
    .toMatch(/\/sw\.js$/);
  return page.evaluate(() => navigator.serviceWorker.controller?.scriptURL ?? '');
}

// The service worker is what this spec is about (playwright.config.ts blocks it elsewhere).
test.use({ serviceWorkers: 'allow' });

test.describe('installable console', () => {
  test.beforeEach(async ({ request }) => {
    await resetSimulators(request);
  });

  test('links a valid manifest whose icons load', async ({ page, request }) => {
    await page.goto('/');
    const href = await page.locator('link[rel="manifest"]').getAttribute('href');
    expect(href).toBe('/manifest.webmanifest');
    const r = await request.get(href ?? '');
    expect(r.status()).toBe(200);
    expect(r.headers()['content-type']).toMatch(/^application\/manifest\+json/);
    expect(r.headers()['cache-control']).toBe('no-cache');
    const m = (await r.json()) as {
      name: string;
      start_url: string;
      display: string;
      icons: Array<{ src: string; sizes: string; purpose?: string }>;
    };
    expect(m).toMatchObject({ name: 'Shopdeck', start_url: '/', display: 'standalone' });
    expect(m.icons.some((i) => i.purpose === 'maskable')).toBe(true);
    // The page itself can load each icon (CSP img-src) at its size.
    const sizes = await page.evaluate(
      (icons) =>
        Promise.all(
          icons.map(async (i) => {
            const img = new Image();
            img.src = i.src;
            await img.decode();
            return `${img.naturalWidth}x${img.naturalHeight}`;
          }),
        ),
      m.icons,
    );
    expect(sizes).toEqual(m.icons.map((i) => i.sizes));
  });

  test('works offline: the app shell says "Console unreachable", never a cached /api or /machines, and recovers', async ({
    page,
    context,
  }, info) => {
    await page.goto('/');
    await expect(page.getByTestId('tile-demo-xtool')).toBeVisible();
    expect(await controlled(page)).toMatch(/^http:\/\/127\.0\.0\.1:\d+\/sw\.js$/);
    // Online, both go to the server.
    expect(await readBoth(page)).toEqual(['HTTP 200', 'HTTP 200']);

    await context.setOffline(true);
    const shell = await page.reload();
    // The shell comes from the worker's precache, with the server's security headers kept.
    expect(shell?.fromServiceWorker()).toBe(true);
    expect(shell?.headers()['content-security-policy']).toContain("script-src 'self';");
    const unreachable = page.getByTestId('console-unreachable');
    await expect(unreachable.getByRole('heading', { name: 'Console unreachable — retrying' })).toBeVisible();
    await expect(unreachable).toContainText('This device has no network.');
    // The app shell, not a browser error page.
    await expect(page.getByRole('link', { name: 'Shopdeck fleet' })).toBeVisible();
    await expect(page.getByRole('button', { name: 'Try now' })).toBeVisible();
    await page.screenshot({ path: info.outputPath('offline.png') });

    // Not answered from a cache: the reads fail, a navigation to them is not the shell.
    expect(await readBoth(page)).toEqual(['failed: TypeError', 'failed: TypeError']);
    for (const url of [API, MACHINE]) {
      const tab = await context.newPage();
      await expect(tab.goto(url)).rejects.toThrow(/ERR_INTERNET_DISCONNECTED/);
      await tab.close();
    }

    // A bookmarked machine page opens offline too (the shell answers the route).
    await page.goto('/m/demo-xtool');
    await expect(page.getByTestId('console-unreachable')).toBeVisible();

    // Back online: it recovers by itself.
    await context.setOffline(false);
    await expect(page.getByTestId('console-unreachable')).toBeHidden();
    await expect(page.getByRole('heading', { level: 1 })).toHaveText('Laser bay — xTool D1 Pro');
    await expect(page.getByTestId('machine-link')).toHaveText('Online');

    // After all that, no cache holds anything of /api or /machines.
    const cached = await cachedUrls(page);
    expect(cached).toContain('/index.html');
    expect(cached.filter((u) => u.startsWith('/api') || u.startsWith('/machines'))).toEqual([]);
  });
});
