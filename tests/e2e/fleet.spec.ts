import { expect, test } from '@playwright/test';
import { DEMO_MACHINES as FAMILIES, resetSimulators } from './simulators';

test.describe('fleet', () => {
  // The simulators run in the server for the whole run: each test starts from a fresh world.
  test.beforeEach(async ({ request }) => {
    await resetSimulators(request);
  });

  test('shows every demo machine with its state in words and opens a bookmarkable machine page', async ({
    page,
  }) => {
    await page.goto('/');
    await expect(page.getByTestId('open-mode-banner')).toBeVisible();
    for (const id of FAMILIES) {
      const tile = page.getByTestId(`tile-${id}`);
      await expect(tile).toBeVisible();
      // Each simulated machine connects: its link badge reads Online and its state is not "Unknown".
      await expect(tile.getByTestId('tile-link')).toHaveText('Online');
      await expect(tile.getByTestId('tile-activity')).not.toHaveText('Unknown');
      await expect(tile.getByText('simulated')).toBeVisible();
    }
    await expect(page.getByTestId('fleet-summary')).toContainText('5 machines');

    // One link per tile: the machine's name.
    const duet = page.getByRole('article', { name: 'Printer bay — Duet 3' });
    await expect(duet.getByRole('link')).toHaveCount(1);
    await duet.getByRole('link', { name: 'Printer bay — Duet 3' }).click();
    await expect(page).toHaveURL(/\/m\/demo-duet$/);
    await expect(page.getByTestId('simulated-banner')).toBeVisible();
    await expect(page.getByTestId('machine-link')).toHaveText('Online');

    // The URL is a bookmark: a fresh load lands on the same machine.
    await page.goto('/m/demo-g2core');
    await expect(page.getByRole('heading', { level: 1 })).toHaveText('CNC router — g2core');
    await page.goto('/m/no-such-machine');
    await expect(page.getByText('There is no machine')).toBeVisible();
  });

  test.describe('first screen', () => {
    // The service worker would fetch the held-back chunks itself (page.route does not see its
    // requests): this test's page has none.
    test.use({ serviceWorkers: 'block' });

    test('the first screen is the console server reading: every tile has a state before any family code', async ({
      page,
    }) => {
      // Every family's code held back: the page can only paint what the machines list carries.
      await page.route(/\/assets\/module-[^/]+\.js$/, (route) => route.abort());
      await expect(async () => {
        await page.goto('/');
        for (const id of FAMILIES) {
          const tile = page.getByTestId(`tile-${id}`);
          await expect(tile.getByTestId('tile-activity')).not.toHaveText('Unknown', { timeout: 1000 });
        }
      }).toPass({ timeout: 20_000 });
      for (const id of FAMILIES) {
        const tile = page.getByTestId(`tile-${id}`);
        await expect(tile.getByTestId('tile-label')).toContainText('Read by the console server');
        // Said for what it is: not a live link yet.
        await expect(tile.getByTestId('tile-link')).toHaveText('Connecting');
      }
      // With the code let through, the same page goes live.
      await page.unroute(/\/assets\/module-[^/]+\.js$/);
      await page.goto('/');
      for (const id of FAMILIES)
        await expect(page.getByTestId(`tile-${id}`).getByTestId('tile-link')).toHaveText('Online');
    });
  });

  test('touch targets on the fleet and machine pages are at least 44 px', async ({ page }, info) => {
    test.skip(info.project.name !== 'tablet', 'tablet layout only');
    await page.goto('/m/demo-xtool');
    await expect(page.getByTestId('machine-link')).toHaveText('Online');
    const small = await page.evaluate(() =>
      [...document.querySelectorAll('main button, nav[aria-label="Machine sections"] a, .topnav a')]
        .filter((el) => (el as HTMLElement).offsetParent !== null)
        .map((el) => ({
          text: (el.textContent ?? '').trim().slice(0, 30),
          h: el.getBoundingClientRect().height,
        }))
        .filter((b) => b.h < 44 && b.h > 0),
    );
    expect(small).toEqual([]);
  });

  test('a dropped simulator shows the machine reconnecting while the others stay online', async ({
    page,
  }) => {
    await page.goto('/m/demo-prunt/simulator');
    await expect(page.getByTestId('machine-link')).toHaveText('Online');
    await page.getByTestId('fault-drop').check();
    await page.getByTestId('fault-close-sockets').click();
    await expect(page.getByTestId('machine-link')).not.toHaveText('Online', { timeout: 30_000 });
    // The fault is the server's simulator's: a fresh load of the fleet still sees it.
    await page.goto('/');
    await expect(page.getByTestId('tile-demo-prunt').getByTestId('tile-link')).not.toHaveText('Online', {
      timeout: 30_000,
    });
    await expect(page.getByTestId('tile-demo-duet').getByTestId('tile-link')).toHaveText('Online');
  });

  test('every tab sees the same simulated world', async ({ page, context }) => {
    await page.goto('/m/demo-xtool/simulator');
    await expect(page.getByTestId('machine-link')).toHaveText('Online');
    const other = await context.newPage();
    await other.goto('/');
    await expect(other.getByTestId('tile-demo-xtool').getByTestId('tile-link')).toHaveText('Online');
    await page.getByTestId('sim-control-flame').click();
    await expect(other.getByTestId('blocking-alarm')).toContainText('FLAME DETECTED');
    await expect(page.getByTestId('blocking-alarm')).toContainText('FLAME DETECTED');
    await other.close();
  });
});
