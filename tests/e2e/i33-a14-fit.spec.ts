import { expect, test, type Page, type TestInfo } from '@playwright/test';
import { DEMO_MACHINES, resetSimulators } from './simulators';

/**
 * Issue 33 (7, 14, "look at every page at 390×844"): every page fits a phone. At 390×844 (set in
 * the test; the tablet project keeps its touch screen, the desktop project its mouse), on every
 * page — sign-in, the fleet as tiles and as a list, each family's machine page with each of its
 * tabs, each family's kiosk page, the alarm centre, history, the audit log, the wall, xTool "Find
 * lasers" — nothing overflows horizontally: the document does not scroll sideways and no visible
 * element ends beyond the right edge (an element inside a container that scrolls or clips
 * sideways, such as a table in its overflow-x:auto wrapper, is that container's business: only
 * the container is measured). The top navigation (the menu button; its pages inside the open
 * menu) and the job's stop controls are on the screen, whole. With SHOPDECK_E2E_SHOTS=1 a
 * screenshot of each page goes to /tmp/a14-<page>.png (to look at; about 80 full-page shots a
 * project, so not in every run).
 * Run: SHOPDECK_E2E_PORT=4196 npx playwright test tests/e2e/i33-a14-fit.spec.ts
 */

const PHONE = { width: 390, height: 844 };
/** Families whose job control row has a stop (TouchCut's controller takes no job commands). */
const WITH_STOP = new Set(['demo-xtool', 'demo-duet', 'demo-prunt', 'demo-g2core']);

interface Overflow {
  what: string;
  right: number;
}

/** What sticks out of the viewport on the right (see above), the document's own sideways scroll first. */
async function overflows(page: Page): Promise<Overflow[]> {
  return page.evaluate(() => {
    const width = window.innerWidth;
    const out: Array<{ what: string; right: number }> = [];
    const doc = document.scrollingElement ?? document.documentElement;
    if (doc.scrollWidth > width)
      out.push({ what: `document scrollWidth ${doc.scrollWidth}`, right: doc.scrollWidth });
    const describe = (el: Element) => {
      const id = el.getAttribute('data-testid');
      const cls =
        typeof el.className === 'string' && el.className
          ? `.${el.className.trim().split(/\s+/).join('.')}`
          : '';
      const text = (el.textContent ?? '').trim().replace(/\s+/g, ' ').slice(0, 40);
      return `${el.tagName.toLowerCase()}${id ? `[data-testid=${id}]` : ''}${cls} "${text}"`;
    };
    /** Inside a box that scrolls or clips sideways (the box itself is measured on its own). */
    const clipped = (el: Element) => {
      for (let p = el.parentElement; p && p !== document.body; p = p.parentElement) {
        const x = getComputedStyle(p).overflowX;
        if (x !== 'visible') return true;
      }
      return false;
    };
    const listed = new Set<Element>();
    for (const el of document.body.querySelectorAll('*')) {
      const r = el.getBoundingClientRect();
      if (r.width === 0 || r.height === 0) continue;
      const style = getComputedStyle(el);
      if (style.visibility === 'hidden' || style.display === 'contents') continue;
      // Screen-reader-only text (clipped to 1 px) is not seen.
      if (style.clip === 'rect(0px, 0px, 0px, 0px)' || style.clipPath === 'inset(50%)') continue;
      if (r.right <= width + 1) continue;
      if (clipped(el)) continue;
      // The outermost offenders only: a child of an element already listed adds nothing.
      if (el.parentElement && [...listed].some((l) => l.contains(el))) continue;
      listed.add(el);
      out.push({ what: describe(el), right: Math.round(r.right) });
    }
    return out.slice(0, 12);
  });
}

/** Whole inside the viewport's width, and in its height once scrolled to. */
async function onScreen(page: Page, selector: string): Promise<boolean> {
  const l = page.locator(selector).first();
  await l.scrollIntoViewIfNeeded();
  const box = await l.boundingBox();
  if (!box) return false;
  return (
    box.x >= 0 && box.x + box.width <= PHONE.width + 1 && box.y >= 0 && box.y + box.height <= PHONE.height + 1
  );
}

async function fits(page: Page, info: TestInfo, name: string, opts: { nav?: boolean; stop?: boolean } = {}) {
  await page.waitForTimeout(500);
  if (process.env.SHOPDECK_E2E_SHOTS)
    await page.screenshot({ path: `/tmp/a14-${name}-${info.project.name}.png`, fullPage: true });
  expect.soft(await overflows(page), `${name}: nothing beyond the right edge at 390 px`).toEqual([]);
  if (opts.nav)
    expect
      .soft(
        await onScreen(page, '[data-testid="topbar-menu-button"]'),
        `${name}: the menu button is on the screen`,
      )
      .toBe(true);
  if (opts.stop) {
    const stops = page.locator(
      '[data-job="stop"] button, [data-job="estop"] button, [data-kiosk="stop"] button',
    );
    expect.soft(await stops.count(), `${name}: a stop control`).toBeGreaterThan(0);
    for (let i = 0; i < (await stops.count()); i++) {
      const s = stops.nth(i);
      await s.scrollIntoViewIfNeeded();
      const box = await s.boundingBox();
      expect
        .soft(
          box !== null &&
            box.x >= 0 &&
            box.x + box.width <= PHONE.width + 1 &&
            box.y + box.height <= PHONE.height + 1,
          `${name}: stop control ${i} (${(await s.textContent()) ?? ''}) on the screen, whole: ${JSON.stringify(box)}`,
        )
        .toBe(true);
    }
    await page.evaluate(() => window.scrollTo(0, 0));
  }
}

test.describe('issue 33: every page fits a 390×844 phone', () => {
  test.beforeEach(async ({ page, request }) => {
    await resetSimulators(request);
    await page.setViewportSize(PHONE);
  });

  test('sign-in page', async ({ page }, info) => {
    await page.route('**/api/session', (route) =>
      route.fulfill({
        contentType: 'application/json',
        body: JSON.stringify({ mode: 'secured', user: null }),
      }),
    );
    await page.goto('/login');
    await expect(page.getByLabel('Password')).toBeVisible();
    await fits(page, info, 'signin');
  });

  test('fleet: tiles, list, the menu with the main pages', async ({ page }, info) => {
    await page.goto('/?view=grid');
    for (const id of DEMO_MACHINES)
      await expect(page.getByTestId(`tile-${id}`).getByTestId('tile-link')).toHaveText('Online', {
        timeout: 20_000,
      });
    await fits(page, info, 'fleet', { nav: true });
    // The main pages, in the open menu on a phone: each whole on the screen.
    await page.getByTestId('topbar-menu-button').click();
    const menu = page.getByTestId('topbar-menu');
    for (const name of ['Fleet', 'Alarms', 'History', 'Audit log']) {
      const link = menu.getByRole('link', { name, exact: false }).first();
      await expect(link).toBeVisible();
      const box = await link.boundingBox();
      expect(box && box.x >= 0 && box.x + box.width <= PHONE.width + 1, `${name} in the menu, whole`).toBe(
        true,
      );
    }
    await fits(page, info, 'fleet-menu');
    await page.keyboard.press('Escape');
    await page.goto('/?view=list');
    await expect(page.getByTestId('fleet-list')).toBeVisible();
    await expect(page.getByTestId('row-demo-duet').getByTestId('row-link')).toHaveText('Online', {
      timeout: 20_000,
    });
    await fits(page, info, 'fleet-list', { nav: true });
  });

  for (const id of DEMO_MACHINES) {
    test(`machine page ${id}, every tab`, async ({ page }, info) => {
      test.slow();
      await page.goto(`/m/${id}`);
      await expect(page.getByTestId('machine-link')).toHaveText('Online', { timeout: 20_000 });
      const sections = page.getByRole('navigation', { name: 'Machine sections' });
      const hrefs = await sections
        .getByRole('link')
        .evaluateAll((as) => as.map((a) => a.getAttribute('href') ?? ''));
      expect(hrefs.length).toBeGreaterThan(2);
      for (const [i, href] of hrefs.entries()) {
        await page.goto(href);
        await expect(page.getByTestId('machine-link')).toHaveText('Online', { timeout: 20_000 });
        const tab = href.split('/')[3] ?? 'first';
        await fits(page, info, `${id.replace('demo-', '')}-${i === 0 ? 'first' : tab}`, {
          nav: true,
          stop: WITH_STOP.has(id),
        });
      }
    });

    test(`kiosk page ${id}`, async ({ page }, info) => {
      await page.goto(`/m/${id}?kiosk`);
      await expect(page.getByTestId('kiosk-link')).toHaveText('Online', { timeout: 20_000 });
      await fits(page, info, `kiosk-${id.replace('demo-', '')}`, { stop: WITH_STOP.has(id) });
    });
  }

  for (const [path, name] of [
    ['/alarms', 'alarms'],
    ['/history', 'history'],
    ['/audit', 'audit'],
    ['/xtool/discover', 'discover'],
  ] as const)
    test(`page ${path}`, async ({ page }, info) => {
      await page.goto(path);
      await expect(page.getByRole('heading', { level: 1 })).toBeVisible();
      // What the page loads (history's charts and tables, the audit's entries) is measured too.
      await expect(page.getByText('Loading…'))
        .toHaveCount(0, { timeout: 20_000 })
        .catch(() => undefined);
      await page.waitForTimeout(1000);
      await fits(page, info, name, { nav: true });
    });

  test('wall screen', async ({ page }, info) => {
    await page.goto('/wall');
    for (const id of DEMO_MACHINES) await expect(page.getByTestId(`wall-card-${id}`)).toBeVisible();
    await fits(page, info, 'wall');
  });
});
