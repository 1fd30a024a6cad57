import { expect, test, type Locator, type Page } from '@playwright/test';

/**
 * Issue 33, item 15 ("temperature charts empty on open"), on a 1024×768 touch tablet: the console's
 * server keeps the last minutes of each machine's temperatures (gateway/temperatures.ts), so a
 * Duet's and a Prunt's chart open with them, not empty, and go on with the live readings. Against
 * the demo fleet's simulators, which the server watches from its start with no page open.
 */

/** The points of the longest line a chart draws (its SVG path: one M, then an L per point). */
async function mostPoints(chart: Locator): Promise<number> {
  const ds = await chart.locator('svg path').evaluateAll((ps) => ps.map((p) => p.getAttribute('d') ?? ''));
  return Math.max(0, ...ds.map((d) => (d.match(/[ML]/g) ?? []).length));
}

/**
 * The seconds a chart's lines cover (TimeSeriesChart: the window spans x 40 to 596 of its 600-wide
 * view box): a page that only draws its own live points covers the seconds since it opened.
 */
async function spanSeconds(chart: Locator, windowS: number): Promise<number> {
  const ds = await chart.locator('svg path').evaluateAll((ps) => ps.map((p) => p.getAttribute('d') ?? ''));
  const xs = ds.flatMap((d) => [...d.matchAll(/[ML](-?[\d.]+),/g)].map((m) => Number(m[1])));
  if (xs.length < 2) return 0;
  return ((Math.max(...xs) - Math.min(...xs)) / (600 - 40 - 4)) * windowS;
}

/** The fleet page shows the demo machines, and the server has watched them for `seconds` since. */
async function demoFleetWatchedFor(page: Page, seconds: number): Promise<void> {
  await page.goto('/');
  await expect(page.getByText('Printer bay — Duet 3').first()).toBeVisible({ timeout: 30_000 });
  await expect(page.getByText('Printer bay — Prunt').first()).toBeVisible();
  // Wall-clock time on purpose: the server samples once a second while no page is open.
  await page.waitForTimeout(seconds * 1000);
}

test.describe('issue 33 item 15: temperature charts start with the server’s last minutes', () => {
  test.beforeEach(({}, info) => {
    test.skip(info.project.name !== 'tablet', 'the tablet (1024×768, touch)');
  });

  test('a Duet’s heater chart has the earlier readings as soon as it opens', async ({ page }) => {
    await demoFleetWatchedFor(page, 12);
    const opened = Date.now();
    await page.goto('/m/demo-duet');
    const chart = page.getByTestId('duet-temp-chart');
    await expect(chart).toBeVisible();
    // Right away: the live socket alone gives one point a second; the server's minutes give more.
    await expect.poll(() => mostPoints(chart), { timeout: 3000 }).toBeGreaterThan(7);
    expect(await spanSeconds(chart, 600)).toBeGreaterThan(8);
    expect(Date.now() - opened).toBeLessThan(10_000);
    await expect(chart.getByRole('img')).toHaveAttribute('aria-label', /^Last 10 min: \d+ readings/);
    expect(Number(await chart.getAttribute('data-readings'))).toBeGreaterThan(7);
    await expect(chart).not.toContainText(/no earlier readings/i);
    // …and it goes on with the live readings: a newer reading within a few seconds (not one more
    // point: once the server has watched for ten minutes the window is full, and it slides).
    const newest = async () => Number(await chart.getAttribute('data-newest'));
    const before = await newest();
    expect(before).toBeGreaterThan(0);
    await expect.poll(newest, { timeout: 8000 }).toBeGreaterThan(before);
    await chart.screenshot({ path: '/tmp/t15-duet-chart.png' });
  });

  test('a Prunt’s live chart has the earlier temperatures as soon as it opens', async ({ page }) => {
    await demoFleetWatchedFor(page, 15);
    await page.goto('/m/demo-prunt');
    const chart = page.getByTestId('prunt-chart');
    await expect(chart.locator('svg')).toBeVisible({ timeout: 15_000 });
    // The page's own ticks come five a second, so count seconds, not points: more than it has
    // been open for.
    await expect.poll(() => spanSeconds(chart, 300), { timeout: 3000 }).toBeGreaterThan(10);
    await expect(chart.getByRole('img')).toHaveAttribute('aria-label', /^Last 5 min: \d+ readings/);
    await expect(chart).not.toContainText(/no earlier readings/i);
    await chart.screenshot({ path: '/tmp/t15-prunt-chart.png' });
  });
});
