import { mkdtempSync, rmSync, writeFileSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import { expect, test, type Locator, type Page } from '@playwright/test';
import { Children, freePort, waitFor } from './own-server';
import { resetSimulators } from './simulators';

/**
 * Issue 33, item 15 (also seen), three of its leftovers:
 *
 * - the wall (a 1920×1080 TV) shows each machine's bay whole and groups by bay: a control on the
 *   wall (only while someone is at the screen: the TV's picture has none), remembered, and set by
 *   the URL (`/wall?group=bay`) so that a TV is configured once;
 * - the fleet grouped by family puts small groups side by side (1440×900 desktop, 1024×768
 *   tablet, 390×844 phone);
 * - the kiosk (1024×768 touch) shows its control row with STOP from the first paint, disabled
 *   with "connecting…" until the family's code and the machine's link are ready, and never
 *   focuses it; the machine page's job control row does the same.
 */

/** Every screenshot of this spec: /tmp/l15-<name>.png (before and after the change). */
const shot = (page: Page, name: string) => page.screenshot({ path: `/tmp/l15-${name}.png` });

/** A bay name of the longest kind the machines file allows (60 characters at most). */
const LONG_BAY = 'Bay 3 — Laser and engraving corner, by the loading door';

/** Printers at an address where nothing answers (port 9, discard): offline cards, no simulator to run. */
const OFFLINE = Array.from({ length: 14 }, (_, i) => ({
  id: `printer-${i + 1}`,
  name: `Printer ${i + 1}`,
  kind: 'duet',
  url: 'http://127.0.0.1:9',
  ...(i < 7 ? { group: LONG_BAY } : i < 10 ? { group: 'Bay 2 — Printing' } : {}),
}));

test.describe('item 15: the wall shows the whole bay name and groups by bay (1920×1080)', () => {
  // A console of its own: its machines file names bays (the shared one names none).
  const children = new Children();
  let dir = '';
  let base = '';
  test.describe.configure({ mode: 'serial' });

  test.beforeAll(async ({}, info) => {
    if (info.project.name !== 'desktop') return;
    dir = mkdtempSync(join(tmpdir(), 'shopdeck-i33-l15-'));
    writeFileSync(
      join(dir, 'machines.json'),
      JSON.stringify({
        machines: [
          { id: 'laser-1', name: 'Laser 1', kind: 'xtool', simulated: true, group: LONG_BAY },
          { id: 'plasma', name: 'Plasma table', kind: 'touchcut', simulated: true, group: 'Bay 1 — Cutting' },
          { id: 'printer-a', name: 'Printer A', kind: 'duet', simulated: true, group: 'Bay 2 — Printing' },
          { id: 'router', name: 'Router', kind: 'g2core', simulated: true, group: 'Bay 1 — Cutting' },
          { id: 'prunt-1', name: 'Prunt 1', kind: 'prunt', simulated: true, group: 'Bay 2 — Printing' },
          { id: 'spare', name: 'Spare router', kind: 'g2core', simulated: true },
          // A shop's worth more (nothing answers at their address: offline), for cards of a real size.
          ...OFFLINE,
        ],
      }),
    );
    const port = await freePort();
    base = `http://127.0.0.1:${port}`;
    children.start(['--import', 'tsx', 'server/main.ts', '--port', String(port), '--host', '127.0.0.1'], {
      SHOPDECK_MACHINES: join(dir, 'machines.json'),
      SHOPDECK_DATA: join(dir, 'data'),
    });
    await waitFor(`${base}/api/session`, 'the console');
  });

  test.afterAll(() => {
    children.stopAll();
    if (dir) rmSync(dir, { recursive: true, force: true });
  });

  /** Whether an element shows all of its text: nothing cut by itself or by its card. */
  async function wholeInside(el: Locator, card: Locator): Promise<void> {
    const clipped = await el.evaluate(
      (e) => e.scrollWidth > e.clientWidth + 1 || e.scrollHeight > e.clientHeight + 1,
    );
    expect(clipped, `${await el.textContent()} is cut`).toBe(false);
    const b = await el.boundingBox();
    const c = await card.boundingBox();
    if (!b || !c) throw new Error('not on screen');
    expect(b.y + b.height, 'inside its card').toBeLessThanOrEqual(c.y + c.height + 1);
    expect(b.x + b.width, 'inside its card').toBeLessThanOrEqual(c.x + c.width + 1);
  }

  const fits = (page: Page) =>
    page.evaluate(
      () =>
        document.documentElement.scrollHeight <= window.innerHeight &&
        document.documentElement.scrollWidth <= window.innerWidth,
    );

  test('15a: each card shows its bay whole; grouping by bay from a control, kept, and from the URL', async ({
    browser,
  }, info) => {
    test.skip(info.project.name !== 'desktop', 'the wall TV: 1920×1080, no touch');
    // Two browsers wait for 20 machines to connect: generous on a busy machine.
    test.setTimeout(180_000);
    const ctx = await browser.newContext({ baseURL: base });
    const page = await ctx.newPage();
    await page.setViewportSize({ width: 1920, height: 1080 });
    await page.goto('/wall');
    const wall = page.getByTestId('wall');
    await expect(wall.getByTestId('wall-card-laser-1')).toHaveAttribute('data-link', 'online');
    await shot(page, 'wall-1920');
    // The bay on each card, whole: the whole name, not cut by an ellipsis or by the card.
    const card = wall.getByTestId('wall-card-laser-1');
    const bay = card.getByTestId('wall-bay');
    await expect(bay).toHaveText(LONG_BAY);
    await wholeInside(bay, card);
    await expect(wall.getByTestId('wall-card-spare').getByTestId('wall-bay')).toHaveCount(0);
    // The TV's picture has no control (nothing to take a stray focus or a click).
    await expect(page.locator('a[href], button, input, select, textarea, [tabindex]')).toHaveCount(0);

    // Someone at the screen (a mouse moved): the view control shows; grouping by bay.
    await page.mouse.move(400, 300);
    await page.mouse.move(420, 320);
    const group = page.getByTestId('wall-group');
    await expect(group).toBeVisible();
    // Offered, never taken: the control does not take the focus by itself.
    expect(await page.evaluate(() => document.activeElement === document.body)).toBe(true);
    await group.selectOption('bay');
    await expect(page).toHaveURL(/\/wall\?group=bay$/);
    const headings = () => wall.locator('[data-testid^="wall-section-"] h2').allTextContents();
    await expect.poll(headings).toEqual(['Bay 1 — Cutting', 'Bay 2 — Printing', LONG_BAY, 'No bay']);
    const section = (name: string) => wall.getByTestId(`wall-section-${name}`);
    await expect(section('Bay 1 — Cutting').getByTestId('wall-card-plasma')).toBeVisible();
    await expect(section('Bay 1 — Cutting').getByTestId('wall-card-router')).toBeVisible();
    await expect(section('Bay 2 — Printing').getByTestId('wall-card-printer-a')).toBeVisible();
    await expect(section('Bay 2 — Printing').getByTestId('wall-card-prunt-1')).toBeVisible();
    await expect(section(LONG_BAY).getByTestId('wall-card-laser-1')).toBeVisible();
    await expect(section('No bay').getByTestId('wall-card-spare')).toBeVisible();
    // Each heading whole, the fleet still on one screen.
    for (const name of ['Bay 1 — Cutting', LONG_BAY, 'No bay'])
      await wholeInside(section(name).locator('h2'), section(name));
    expect(await fits(page)).toBe(true);
    await shot(page, 'wall-1920-by-bay');

    // Kept: the wall opened again (no query) is grouped by bay; the control hides again.
    await page.goto('/wall');
    await expect.poll(headings).toEqual(['Bay 1 — Cutting', 'Bay 2 — Printing', LONG_BAY, 'No bay']);
    await expect(page.locator('a[href], button, input, select, textarea, [tabindex]')).toHaveCount(0);
    // And back to one grid.
    await page.mouse.move(500, 500);
    await page.mouse.move(510, 510);
    await page.getByTestId('wall-group').selectOption('none');
    await expect(page).toHaveURL(/\/wall$/);
    await expect(wall.locator('[data-testid^="wall-section-"]')).toHaveCount(0);
    await ctx.close();

    // A TV configured once by its URL: a fresh browser, no pointer, grouped by bay.
    const tv = await browser.newContext({ baseURL: base, viewport: { width: 1920, height: 1080 } });
    const tvPage = await tv.newPage();
    await tvPage.goto('/wall?group=bay');
    const tvWall = tvPage.getByTestId('wall');
    await expect(tvWall.getByTestId('wall-card-laser-1')).toHaveAttribute('data-link', 'online');
    await expect
      .poll(() => tvWall.locator('[data-testid^="wall-section-"] h2').allTextContents())
      .toEqual(['Bay 1 — Cutting', 'Bay 2 — Printing', LONG_BAY, 'No bay']);
    await expect(tvPage.locator('a[href], button, input, select, textarea, [tabindex]')).toHaveCount(0);
    expect(await fits(tvPage)).toBe(true);
    // Kept by that browser: the plain /wall of the same TV stays grouped.
    await tvPage.goto('/wall');
    await expect(tvWall.locator('[data-testid^="wall-section-"]')).toHaveCount(4);
    await tv.close();
  });
});

test.describe('item 15: family groups share rows', () => {
  test.beforeEach(async ({ request }) => {
    await resetSimulators(request);
  });

  /** The tops of the family groups, in page order, and the tiles' boxes. */
  async function layout(page: Page) {
    await page.goto('/?group=family');
    const groups = page.locator('[data-testid^="fleet-group-family:"]');
    await expect(groups).toHaveCount(5);
    await expect(page.getByTestId('tile-demo-g2core').getByTestId('tile-link')).toHaveText('Online');
    const tops = await groups.evaluateAll((els) => els.map((e) => Math.round(e.getBoundingClientRect().top)));
    const widths = await page
      .locator('[data-testid^="tile-demo-"]')
      .evaluateAll((els) => els.map((e) => Math.round(e.getBoundingClientRect().width)));
    const overflow = await page.evaluate(
      () => document.documentElement.scrollWidth - document.documentElement.clientWidth,
    );
    return { tops, widths, overflow, rows: new Set(tops).size };
  }

  test('15b: at 1440×900 the one-tile family groups sit side by side', async ({ page }, info) => {
    test.skip(info.project.name !== 'desktop', 'the 1440×900 desktop');
    const l = await layout(page);
    await shot(page, 'fleet-family-1440');
    // Five groups of one tile: four on the first row, not one row each.
    expect(l.rows).toBeLessThanOrEqual(2);
    expect(l.tops.slice(0, 4).every((t) => t === l.tops[0])).toBe(true);
    // Tiles as wide as in the ungrouped grid (300 px or more), not stretched across the screen.
    for (const w of l.widths) {
      expect(w).toBeGreaterThanOrEqual(300);
      expect(w).toBeLessThanOrEqual(480);
    }
    expect(l.overflow).toBeLessThanOrEqual(0);
  });

  test('15b: the tablet (1024×768) puts groups side by side, the phone (390×844) one under the other', async ({
    page,
  }, info) => {
    test.skip(info.project.name !== 'tablet', 'the 1024×768 touch tablet, and a phone');
    const t = await layout(page);
    await shot(page, 'fleet-family-1024');
    expect(t.rows).toBeLessThanOrEqual(2);
    expect(t.tops.slice(0, 3).every((y) => y === t.tops[0])).toBe(true);
    for (const w of t.widths) expect(w).toBeGreaterThanOrEqual(280);
    expect(t.overflow).toBeLessThanOrEqual(0);

    await page.setViewportSize({ width: 390, height: 844 });
    const p = await layout(page);
    await shot(page, 'fleet-family-390');
    // One column: each group under the last, each tile within the screen.
    expect(p.rows).toBe(5);
    for (const w of p.widths) expect(w).toBeLessThanOrEqual(390);
    expect(p.overflow).toBeLessThanOrEqual(0);
  });
});

test.describe('item 15: the kiosk shows STOP from the first paint, disabled while connecting', () => {
  // The service worker would fetch the held-back chunk itself (page.route does not see it).
  test.use({ serviceWorkers: 'block' });

  test.beforeEach(async ({ request }, info) => {
    test.skip(info.project.name !== 'tablet', 'the 1024×768 touch tablet');
    await resetSimulators(request, ['demo-xtool']);
  });

  /** Holds the families' code until `release()` (as a slow network would, for as long as asked). */
  async function holdFamilyCode(page: Page): Promise<() => void> {
    let release!: () => void;
    const held = new Promise<void>((r) => (release = r));
    await page.route(/\/assets\/module-[^/]+\.js$/, async (route) => {
      await held;
      await route.continue();
    });
    return release;
  }

  const focusInRow = (page: Page) =>
    page.evaluate(() => {
      const el = document.activeElement;
      return !!el && el !== document.body && !!el.closest('[data-testid="job-controls"]');
    });

  for (const where of [
    { name: 'kiosk', path: '/m/demo-xtool?kiosk', stop: '[data-kiosk="stop"] button' },
    { name: 'machine page', path: '/m/demo-xtool', stop: '[data-job="stop"] button' },
  ] as const) {
    test(`15c: the ${where.name} shows its job control row at once, stop disabled "connecting…"`, async ({
      page,
    }) => {
      const release = await holdFamilyCode(page);
      const sent: string[] = [];
      page.on('request', (r) => {
        if (r.method() !== 'GET' && r.url().includes('/machines/demo-xtool/')) sent.push(r.url());
      });
      await page.goto(where.path);
      const row = page.getByTestId('job-controls');
      const stop = page.locator(where.stop);
      // The family's code is still held back: the row is there, with stop, disabled and saying why.
      await expect(stop).toBeVisible();
      await expect(stop).toHaveAttribute('aria-disabled', 'true');
      await expect(row.locator('[data-job="stop"]')).toContainText(/connecting…/i);
      await expect(row.locator('[data-job="pause"]')).toContainText(/connecting…/i);
      await expect(row.getByRole('button', { name: 'Stop job', exact: true })).toBeVisible();
      await shot(page, `${where.name === 'kiosk' ? 'kiosk' : 'machine'}-connecting-1024`);
      expect(await focusInRow(page)).toBe(false);
      // A tap does nothing: no question, nothing sent.
      await stop.tap({ force: true });
      await expect(page.getByTestId('confirm-dialog')).toHaveCount(0);
      expect(sent).toEqual([]);

      // The code arrives, the machine answers: the same row, live, with no "connecting…" left.
      release();
      await expect(page.getByTestId(where.name === 'kiosk' ? 'kiosk-link' : 'machine-link')).toHaveText(
        'Online',
      );
      await expect(row.locator('[data-job="stop"]')).not.toContainText(/connecting/i);
      await expect(stop).toHaveAttribute('data-testid', 'cmd-xtool.stop');
      expect(await focusInRow(page)).toBe(false);
      await shot(page, `${where.name === 'kiosk' ? 'kiosk' : 'machine'}-online-1024`);
    });
  }
});
