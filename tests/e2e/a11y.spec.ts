import AxeBuilder from '@axe-core/playwright';
import { expect, test, type Page, type TestInfo } from '@playwright/test';
import { resetSimulators } from './simulators';

/**
 * Accessibility: axe on every page of the console, at the tablet and the desktop size (the two
 * projects of playwright.config.ts), in the light and the dark theme. A serious or critical
 * violation fails the test; the full axe answer is attached to the report.
 *
 * Pages: the fleet, each family's machine page and each of its tabs (open mode: the supervisor
 * sees them all), the family pages (xTool "Find lasers"), the audit page, the alarm centre, the
 * history page, the wall screen, the top bar's open menu and the login page; and
 * the dialogs: a confirmation, a Duet message box, the blocking alarm.
 * Navigation is in-app. The simulators run in the server: each test starts from a fresh world.
 */

const MACHINES = ['demo-xtool', 'demo-touchcut', 'demo-duet', 'demo-prunt', 'demo-g2core'];
const FAILING = new Set(['serious', 'critical']);

async function audit(page: Page, info: TestInfo, what: string): Promise<void> {
  for (const scheme of ['light', 'dark'] as const) {
    await page.emulateMedia({ colorScheme: scheme });
    const results = await new AxeBuilder({ page })
      .withTags(['wcag2a', 'wcag2aa', 'wcag21a', 'wcag21aa', 'wcag22aa', 'best-practice'])
      .analyze();
    const bad = results.violations.filter((v) => FAILING.has(v.impact ?? ''));
    if (bad.length)
      await info.attach(`axe ${what} (${scheme})`, {
        body: JSON.stringify(bad, null, 2),
        contentType: 'application/json',
      });
    expect
      .soft(
        bad.map(
          (v) =>
            `${v.id} [${v.impact}] ${v.help}: ${v.nodes
              .slice(0, 4)
              .map(
                (n) =>
                  `${n.target.join(' ')}${n.failureSummary ? ` — ${n.failureSummary.split('\n')[1]?.trim() ?? ''}` : ''}`,
              )
              .join(' | ')}${v.nodes.length > 4 ? ` (+${v.nodes.length - 4} more)` : ''}`,
        ),
        `${what} (${scheme} theme)`,
      )
      .toEqual([]);
  }
  await page.emulateMedia({ colorScheme: null });
}

/** In-app navigation, as a click on a link would do. */
async function go(page: Page, path: string): Promise<void> {
  await page.evaluate((p) => {
    history.pushState(null, '', p);
    window.dispatchEvent(new PopStateEvent('popstate'));
  }, path);
}

function sections(page: Page) {
  return page.getByRole('navigation', { name: 'Machine sections' });
}

test.describe('accessibility (axe)', () => {
  test.beforeEach(async ({ request }) => {
    await resetSimulators(request);
  });

  test('fleet page', async ({ page }, info) => {
    await page.goto('/');
    for (const id of MACHINES)
      await expect(page.getByTestId(`tile-${id}`).getByTestId('tile-link')).toHaveText('Online');
    await audit(page, info, 'fleet');
  });

  for (const id of MACHINES) {
    test(`machine page ${id}, every tab`, async ({ page }, info) => {
      // An axe run per tab: 20–50 s on this machine, more when it is busy (CI once hit 60 s).
      test.slow();
      await page.goto(`/m/${id}`);
      await expect(page.getByTestId('machine-link')).toHaveText('Online');
      const names = await sections(page).getByRole('link').allInnerTexts();
      expect(names.length).toBeGreaterThan(2);
      for (const name of names) {
        const link = sections(page).getByRole('link', { name, exact: true });
        await link.click();
        await expect(link).toHaveAttribute('aria-current', 'page');
        // Let the tab fetch what it shows (its first answer, or its error).
        await page.waitForTimeout(700);
        await audit(page, info, `${id} · ${name}`);
      }
    });
  }

  test('family page: xTool "Find lasers"', async ({ page }, info) => {
    await page.goto('/');
    await page.getByTestId('topbar-menu-button').click();
    await page.getByTestId('topbar-menu').getByRole('link', { name: 'Find lasers' }).click();
    await expect(page).toHaveURL(/\/xtool\/discover$/);
    await page.waitForTimeout(500);
    await audit(page, info, 'xtool discover');
  });

  test('audit page', async ({ page }, info) => {
    await page.goto('/');
    await page.getByTestId('topbar-menu-button').click();
    await page.getByTestId('topbar-menu').getByRole('link', { name: 'Audit log' }).click();
    await expect(page).toHaveURL(/\/audit$/);
    await page.waitForTimeout(700);
    await audit(page, info, 'audit');
  });

  test('alarm centre', async ({ page }, info) => {
    await page.goto('/');
    await page.getByRole('navigation', { name: 'Main' }).getByRole('link', { name: 'Alarms' }).click();
    await expect(page).toHaveURL(/\/alarms$/);
    await expect(page.getByRole('heading', { level: 1, name: 'Alarm centre' })).toBeVisible();
    await page.waitForTimeout(700);
    await audit(page, info, 'alarms');
  });

  test('history page', async ({ page }, info) => {
    await page.goto('/');
    await page.getByRole('navigation', { name: 'Main' }).getByRole('link', { name: 'History' }).click();
    await expect(page).toHaveURL(/\/history$/);
    await expect(page.getByRole('heading', { level: 1, name: 'Production history' })).toBeVisible();
    await page.waitForTimeout(700);
    await audit(page, info, 'history');
  });

  test('the top bar’s menu, open', async ({ page }, info) => {
    await page.goto('/');
    await page.getByTestId('topbar-menu-button').click();
    await expect(page.getByTestId('topbar-menu').getByLabel('Theme')).toBeVisible();
    await audit(page, info, 'top bar menu');
  });

  test('wall screen', async ({ page }, info) => {
    await page.goto('/wall');
    await expect(page).toHaveTitle('Wall screen · Shopdeck');
    await page.waitForTimeout(700);
    await audit(page, info, 'wall');
  });

  test('login page', async ({ page }, info) => {
    await page.route('**/api/session', (route) =>
      route.fulfill({
        contentType: 'application/json',
        body: JSON.stringify({ mode: 'secured', user: null }),
      }),
    );
    await page.goto('/login');
    await expect(page.getByLabel('Password')).toBeVisible();
    await audit(page, info, 'login');
  });

  test('dialogs: a confirmation, a Duet message box, the blocking alarm', async ({ page }, info) => {
    await page.goto('/m/demo-duet/files');
    await expect(page.getByTestId('machine-link')).toHaveText('Online');
    await page.getByTestId('duet-start-bracket.gcode').click();
    await expect(page.getByRole('alertdialog')).toBeVisible();
    await audit(page, info, 'confirmation');
    await page.keyboard.press('Escape');
    await expect(page.getByRole('alertdialog')).toHaveCount(0);

    await sections(page).getByRole('link', { name: 'Simulator' }).click();
    await page.getByRole('button', { name: 'Message box: integer' }).click();
    await sections(page).getByRole('link', { name: 'Status' }).click();
    await expect(page.getByRole('dialog')).toBeVisible();
    await audit(page, info, 'Duet message box');

    await go(page, '/m/demo-xtool/simulator');
    await expect(page.getByTestId('machine-link')).toHaveText('Online');
    await page.getByRole('button', { name: 'Flame under the laser' }).click();
    await expect(page.getByRole('alertdialog', { name: 'Critical alarm' })).toBeVisible();
    await audit(page, info, 'blocking alarm');
  });
});
