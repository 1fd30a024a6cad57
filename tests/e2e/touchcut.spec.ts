import { expect, test, type Page } from '@playwright/test';
import { resetSimulators } from './simulators';

/**
 * Kinetic TouchCut against the simulated plasma table `demo-touchcut` (its simulator runs in the
 * console's server). The simulator is built from the manual only; it stands in for the API key a
 * gateway would add for a real machine too.
 */

const ID = 'demo-touchcut';

async function actAs(page: Page, name: string, role: 'operator' | 'supervisor'): Promise<void> {
  await page.route('**/api/session', (route) =>
    route.fulfill({
      contentType: 'application/json',
      body: JSON.stringify({ mode: 'secured', user: { name, role, machines: null } }),
    }),
  );
}

test.describe('Kinetic TouchCut', () => {
  // The simulators run in the server for the whole run: each test starts from a fresh world.
  test.beforeEach(async ({ request }) => {
    await resetSimulators(request, [ID]);
  });

  test('a supervisor picks last week and reads the consumables', async ({ page }, info) => {
    test.skip(info.project.name !== 'desktop', 'desktop layout only');
    await actAs(page, 'sue', 'supervisor');
    await page.goto(`/m/${ID}/stats`);
    await expect(page.getByTestId('machine-link')).toHaveText('Online');
    await expect(page.getByTestId('touchcut-stats')).toBeVisible();

    await page.getByTestId('stats-preset-lastWeek').click();
    await expect(page.getByTestId('stats-preset-lastWeek')).toHaveAttribute('aria-pressed', 'true');
    await expect(page.getByTestId('stats-days')).toContainText('(7 days)');
    const from = await page.getByTestId('stats-start').inputValue();
    const until = await page.getByTestId('stats-end').inputValue();
    // Last week: Monday to the next Monday (not included).
    expect(new Date(`${from}T12:00:00`).getDay()).toBe(1);
    expect((Date.parse(until) - Date.parse(from)) / 86_400_000).toBe(7);

    const totals = page.getByTestId('stats-consumable-totals');
    await expect(totals).toBeVisible();
    for (const t of ['Electrode', 'Nozzle', 'Shield', 'Swirl Ring']) await expect(totals).toContainText(t);
    await expect(page.getByTestId('stats-summary')).toContainText('Starts, all tools (pierces)');

    // Every table exports CSV.
    const download = page.waitForEvent('download');
    await page.getByTestId(`csv-touchcut-consumable-totals-${from}-to-${until}`).click();
    const file = await download;
    expect(file.suggestedFilename()).toBe(`touchcut-consumable-totals-${from}_to_${until}.csv`);
  });

  test('an operator watches the live screenshot on the tablet', async ({ page }, info) => {
    test.skip(info.project.name !== 'tablet', 'tablet layout only');
    await actAs(page, 'olga', 'operator');
    const shots: number[] = [];
    page.on('request', (r) => {
      if (r.url().includes(`/machines/${ID}/rest/v1/screenshot`)) shots.push(Date.now());
    });
    await page.goto(`/m/${ID}/screen`);
    await expect(page.getByTestId('machine-link')).toHaveText('Online');
    const img = page.getByTestId('screen-image');
    await expect(img).toBeVisible();
    await expect(page.getByTestId('screen-age')).toContainText(/image from \d+ sec\.? ago/);
    const first = await img.getAttribute('src');
    await expect.poll(() => img.getAttribute('src'), { timeout: 5000 }).not.toBe(first);

    // Never more than one request per second.
    await page.waitForTimeout(3000);
    const seen = shots.filter((t) => t >= shots[0]!);
    const span = (seen.at(-1)! - seen[0]!) / 1000;
    expect(seen.length).toBeLessThanOrEqual(Math.floor(span) + 2);

    // Big touch targets; pause stops the requests.
    const pause = page.getByTestId('screen-pause');
    expect((await pause.boundingBox())?.height ?? 0).toBeGreaterThanOrEqual(44);
    expect((await page.getByTestId('screen-fullscreen').boundingBox())?.height ?? 0).toBeGreaterThanOrEqual(
      44,
    );
    await pause.tap();
    await expect(page.getByTestId('screen-age')).toContainText('Paused');
    const before = shots.length;
    await page.waitForTimeout(2500);
    // (a fleet tile is not on this page: nobody else watches)
    expect(shots.length).toBeLessThanOrEqual(before + 1);
    await expect(page.getByText('SIMULATED', { exact: true })).toBeVisible();
    // No invented controls: the console says control happens at the machine.
    await expect(page.getByTestId('touchcut-read-only')).toBeVisible();
  });
});
