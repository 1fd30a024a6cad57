import { expect, test, type Page, type TestInfo } from '@playwright/test';
import { axeCheck } from './axe';
import { DEMO_MACHINES, resetSimulators } from './simulators';

/**
 * Issue 33 (14): axe clean on every page. Every page of the console, at the tablet (1024×768
 * touch) and the desktop (1440×900) size (the two projects of playwright.config.ts), in the light
 * and the dark theme: the sign-in page, the fleet as tiles and as a list (and the touch "View"
 * fold open), each family's machine page with each of its tabs, each family's kiosk page, the
 * alarm centre, history, the audit log, the wall, the family pages (xTool "Find lasers"), the
 * top bar's open menu and the page for an unknown address. Unlike a11y.spec.ts (serious and
 * critical only), ANY violation fails, whatever its impact: "clean" means none.
 * Run: SHOPDECK_E2E_PORT=4196 npx playwright test tests/e2e/i33-a14-axe.spec.ts
 */

async function axeClean(page: Page, info: TestInfo, what: string): Promise<void> {
  await axeCheck(page, info, what);
}

async function fleetOnline(page: Page, path = '/'): Promise<void> {
  await page.goto(path);
  for (const id of DEMO_MACHINES)
    await expect(page.getByTestId(`tile-${id}`).or(page.getByTestId(`row-${id}`))).toBeVisible({
      timeout: 20_000,
    });
}

function sections(page: Page) {
  return page.getByRole('navigation', { name: 'Machine sections' });
}

test.describe('issue 33 (14): axe clean on every page', () => {
  test.beforeEach(async ({ request }) => {
    await resetSimulators(request);
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
    await axeClean(page, info, 'sign-in');
  });

  test('fleet: tiles, the list, the open menu', async ({ page }, info) => {
    test.slow();
    await fleetOnline(page, '/?view=grid');
    for (const id of DEMO_MACHINES)
      await expect(page.getByTestId(`tile-${id}`).getByTestId('tile-link')).toHaveText('Online');
    await axeClean(page, info, 'fleet tiles');
    const fold = page.getByTestId('fleet-view-fold');
    if (await fold.isVisible()) {
      await fold.locator('summary').click();
      await expect(page.getByTestId('fleet-filter')).toBeVisible();
      await axeClean(page, info, 'fleet tiles, View open');
    }
    await fleetOnline(page, '/?view=list');
    await expect(page.getByTestId('fleet-list')).toBeVisible();
    for (const id of DEMO_MACHINES)
      await expect(page.getByTestId(`row-${id}`).getByTestId('row-link')).toHaveText('Online');
    await axeClean(page, info, 'fleet list');
    await page.getByTestId('topbar-menu-button').click();
    await expect(page.getByTestId('topbar-menu').getByLabel('Theme')).toBeVisible();
    await axeClean(page, info, 'top bar menu');
  });

  for (const id of DEMO_MACHINES) {
    test(`machine page ${id}, every tab`, async ({ page }, info) => {
      test.slow();
      await page.goto(`/m/${id}`);
      await expect(page.getByTestId('machine-link')).toHaveText('Online', { timeout: 20_000 });
      const names = await sections(page).getByRole('link').allInnerTexts();
      expect(names.length).toBeGreaterThan(2);
      for (const name of names) {
        const link = sections(page).getByRole('link', { name, exact: true });
        await link.click();
        await expect(link).toHaveAttribute('aria-current', 'page');
        await page.waitForTimeout(700);
        await axeClean(page, info, `${id} · ${name}`);
      }
    });

    test(`kiosk page ${id}`, async ({ page }, info) => {
      await page.goto(`/m/${id}?kiosk`);
      await expect(page.getByTestId('kiosk-link')).toHaveText('Online', { timeout: 20_000 });
      await page.waitForTimeout(700);
      await axeClean(page, info, `${id} kiosk`);
    });
  }

  for (const [path, heading] of [
    ['/alarms', 'Alarm centre'],
    ['/history', 'Production history'],
    ['/audit', null],
    ['/xtool/discover', null],
    ['/no/such/page', null],
  ] as const)
    test(`page ${path}`, async ({ page }, info) => {
      test.slow();
      await page.goto(path);
      if (heading) await expect(page.getByRole('heading', { level: 1, name: heading })).toBeVisible();
      else await expect(page.getByRole('heading', { level: 1 }).first()).toBeAttached();
      await page.waitForTimeout(1000);
      await axeClean(page, info, path);
    });

  test('wall screen', async ({ page }, info) => {
    await page.goto('/wall');
    await expect(page).toHaveTitle('Wall screen · Shopdeck');
    for (const id of DEMO_MACHINES) await expect(page.getByTestId(`wall-card-${id}`)).toBeVisible();
    await page.waitForTimeout(700);
    await axeClean(page, info, 'wall');
  });
});
