import { expect, test, type Page } from '@playwright/test';
import { resetSimulators } from './simulators';

/**
 * The pen test, in a browser: a controller's help text, update URL and file names try to make the
 * console's page reach other machines (`%2e%2e/acc-laser/system?action=…`) or the console's API.
 * The simulated Prunt (`demo-prunt`, its simulator in the console's server) answers; an init
 * script rewrites its answers on their way into the app, so the attack arrives
 * exactly where a hostile controller would put it. Nothing may be requested outside
 * `/machines/demo-prunt/`, and no link may lead anywhere but an external https page.
 *
 * The unit tests (src/ui/safe-url.test.ts, src/forms/sanitize.test.ts, src/controllers/prunt/…)
 * perform each attack one by one; this checks the same in a real browser's URL parser.
 */

const ID = 'demo-prunt';

/** A section of the machine page: a link in the "Machine sections" navigation. */
function section(page: Page, name: string) {
  return page.getByRole('navigation', { name: 'Machine sections' }).getByRole('link', { name, exact: true });
}

const IMAGE_ATTACKS = [
  '%2e%2e/acc-laser/system?action=setFlameAlarmMode&flameAlarmMode=1',
  '%2E%2E/demo-g2core/machine/panic',
  '.%2e/demo-xtool/cnc/data?action=stop',
  '..%2fdemo-xtool/cnc/data?action=stop',
  '..\\demo-xtool\\cnc\\data?action=stop',
  '\\\\evil.example/x.png',
  '//evil.example/x.png',
  '/machines/demo-duet/machine/code?gcode=M112',
  '/api/users',
  'java\tscript:alert(1)',
  'data:image/svg+xml,<svg xmlns="http://www.w3.org/2000/svg" onload="alert(1)"/>',
];
const LINK_ATTACKS = [
  '%2e%2e/demo-g2core/machine/panic',
  '/api/audit.csv',
  'javascript:alert(document.cookie)',
  'java\tscript:alert(1)',
  'http://evil.example/',
  'data:text/html,<script>alert(1)</script>',
];
const PAYLOAD =
  IMAGE_ATTACKS.map((s) => `<img src="${s}" srcset="${s} 2x">`).join('') +
  LINK_ATTACKS.map((h) => `<a href="${h}">bad link</a>`).join('') +
  '<a href="https://prunt3d.com/docs">good link</a>' +
  '<base href="/machines/demo-xtool/"><meta http-equiv="refresh" content="0;url=/api/users">' +
  '<link rel="stylesheet" href="/machines/demo-xtool/cnc/data?action=stop">' +
  '<p style="background:url(/machines/demo-xtool/cnc/data?action=stop)">styled</p>' +
  '<form><button formaction="/machines/demo-g2core/machine/panic">go</button></form>';

/** Rewrites the simulated controller's answers before the app reads them. */
async function hostileController(page: Page): Promise<void> {
  await page.addInitScript(
    ({ id, payload }) => {
      // The hostile answers are made by wrapping fetch: the page's read socket (src/fleet/read-socket.ts)
      // is refused here, so the page reads over HTTP, as it does whenever that socket is not open.
      const NativeSocket = window.WebSocket;
      window.WebSocket = class extends NativeSocket {
        constructor(url: string | URL, protocols?: string | string[]) {
          if (String(url).includes('/api/reads')) throw new Error('the read socket is refused in this test');
          super(url, protocols);
        }
      };
      const original = window.fetch.bind(window);
      window.fetch = async (input: RequestInfo | URL, init?: RequestInit) => {
        const res = await original(input, init);
        const url = typeof input === 'string' ? input : input instanceof URL ? input.href : input.url;
        const path = new URL(url, location.href).pathname;
        const json = (body: unknown) =>
          new Response(JSON.stringify(body), {
            status: res.status,
            headers: { 'Content-Type': 'application/json' },
          });
        if (path === `/machines/${id}/config/schema`) {
          const text = await res.text();
          // Every help text of every setting carries the attack.
          return new Response(
            text.replace(
              /"Description"\s*:\s*"/g,
              () =>
                `"Description":"${payload.replace(/\\/g, '\\\\').replace(/"/g, '\\"').replace(/\t/g, '\\t')}`,
            ),
            { status: res.status, headers: res.headers },
          );
        }
        if (path === `/machines/${id}/update-check` || path === `/machines/${id}/update_check`)
          return json({
            Available: true,
            URL: '/machines/acc-laser/system?action=setFlameAlarmMode&flameAlarmMode=1',
          });
        if (path === `/machines/${id}/uploads/`)
          return json(['benchy.gcode', '..', '../../acc-laser/system?action=stop', '%2e%2e']);
        return res;
      };
    },
    { id: ID, payload: PAYLOAD },
  );
}

/** Every URL the page asked for (network or service worker), from the browser's own records. */
async function requestedUrls(page: Page): Promise<string[]> {
  return page.evaluate(() => performance.getEntriesByType('resource').map((e) => e.name));
}

/**
 * The URLs the attack named. The console polls every machine of the demo fleet all along (status
 * reports, file lists), so only the attack's own targets count: none of them may be requested.
 */
function outside(urls: string[], origin: string): string[] {
  return urls.filter((u) => {
    const url = new URL(u, origin);
    if (url.origin !== origin) return true;
    const full = url.pathname + url.search;
    return /acc-laser|machine\/panic|action=stop|action=setFlameAlarmMode|gcode=M112|\/api\/(users|audit)/.test(
      full,
    );
  });
}

test.describe('controller-supplied links and images stay on their machine', () => {
  test.beforeEach(async ({ request }) => {
    await resetSimulators(request, [ID]);
  });

  test('Help text: no image outside /machines/demo-prunt/, links only to external https', async ({
    page,
  }, info) => {
    test.skip(info.project.name !== 'desktop', 'desktop layout only');
    const seen: string[] = [];
    page.on('request', (r) => seen.push(r.url()));
    const dialogs: string[] = [];
    page.on('dialog', (d) => {
      dialogs.push(d.message());
      void d.dismiss();
    });
    await hostileController(page);
    await page.goto(`/m/${ID}`);
    await expect(page.getByTestId('machine-link')).toHaveText('Online');
    await section(page, 'Config').click();
    await expect(page.getByTestId('form-view')).toBeVisible();
    await page.getByTestId('section-Steppers').click();
    const helps = page.locator('button.fm-help', { hasText: 'Help' });
    await expect(helps.first()).toBeVisible();
    for (const b of await helps.all()) if (await b.isVisible()) await b.click();
    const bodies = page.locator('.fm-desc-body');
    await expect(bodies.first()).toBeVisible();
    await page.waitForTimeout(500); // let any image request start

    const origin = new URL(page.url()).origin;
    const imgs = await bodies.locator('img').evaluateAll((els) =>
      els.map((e) => ({
        src: e.getAttribute('src'),
        srcset: e.getAttribute('srcset'),
        resolved: (e as HTMLImageElement).currentSrc || (e as HTMLImageElement).src,
      })),
    );
    for (const i of imgs) {
      expect(i.srcset).toBeNull();
      expect(new URL(i.resolved).origin).toBe(origin);
      expect(new URL(i.resolved).pathname.startsWith(`/machines/${ID}/`)).toBe(true);
    }
    const links = await bodies.locator('a').evaluateAll((els) =>
      els.map((e) => ({
        href: (e as HTMLAnchorElement).href,
        rel: e.getAttribute('rel'),
        target: e.getAttribute('target'),
      })),
    );
    expect(links.length).toBeGreaterThan(0);
    for (const l of links) {
      expect(l.href).toBe('https://prunt3d.com/docs');
      expect(l.rel).toBe('noopener noreferrer');
      expect(l.target).toBe('_blank');
    }
    await expect(bodies.first()).toContainText('bad link'); // unwrapped to text
    expect(
      await page.locator('.fm-desc-body [style], .fm-desc-body form, .fm-desc-body button').count(),
    ).toBe(0);
    expect(await page.locator('base, meta[http-equiv], link[href*="demo-xtool"]').count()).toBe(0);

    expect(outside(seen, origin)).toEqual([]);
    expect(outside(await requestedUrls(page), origin)).toEqual([]);
    expect(dialogs).toEqual([]);
    expect(new URL(page.url()).pathname).toBe(`/m/${ID}/config`);
  });

  test('update URL and file names: text, not links out of the machine', async ({ page }, info) => {
    test.skip(info.project.name !== 'desktop', 'desktop layout only');
    const seen: string[] = [];
    page.on('request', (r) => seen.push(r.url()));
    await hostileController(page);
    await page.goto(`/m/${ID}`);
    await expect(page.getByTestId('machine-link')).toHaveText('Online');
    await section(page, 'Files').click();
    await expect(page.getByTestId('prunt-files')).toContainText('benchy.gcode');
    await page.getByRole('button', { name: 'Check result again' }).click();
    const update = page.getByTestId('prunt-update-url');
    await expect(update).toContainText('acc-laser');
    expect(await update.evaluate((e) => e.tagName)).toBe('SPAN');
    const hrefs = await page
      .getByTestId('prunt-files')
      .locator('a[href]')
      .evaluateAll((els) => els.map((e) => (e as HTMLAnchorElement).href));
    const origin = new URL(page.url()).origin;
    for (const h of hrefs) expect(new URL(h).pathname.startsWith(`/machines/${ID}/uploads/`)).toBe(true);
    expect(await page.getByTestId('download-..').evaluate((e) => e.tagName)).toBe('SPAN');
    expect(outside(seen, origin)).toEqual([]);
  });
});
