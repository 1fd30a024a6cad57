import { expect, test, type Page } from '@playwright/test';
import { axeCheck } from './axe';
import { resetSimulators } from './simulators';

/**
 * Accessibility: axe on the console's dialogs, at the tablet and the desktop size (the two
 * projects of playwright.config.ts), in the light and the dark theme: a confirmation, a Duet
 * message box, the blocking alarm. A serious or critical violation fails the test; the full axe
 * answer is attached to the report. Every page and tab is checked in i33-a14-axe.spec.ts, where
 * any violation fails.
 * Navigation is in-app. The simulators run in the server: each test starts from a fresh world.
 */

const FAILING = new Set(['serious', 'critical']);

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

  test('dialogs: a confirmation, a Duet message box, the blocking alarm', async ({ page }, info) => {
    await page.goto('/m/demo-duet/files');
    await expect(page.getByTestId('machine-link')).toHaveText('Online');
    await page.getByTestId('duet-start-bracket.gcode').click();
    await expect(page.getByRole('alertdialog')).toBeVisible();
    await axeCheck(page, info, 'confirmation', FAILING);
    await page.keyboard.press('Escape');
    await expect(page.getByRole('alertdialog')).toHaveCount(0);

    await sections(page).getByRole('link', { name: 'Simulator' }).click();
    await page.getByRole('button', { name: 'Message box: integer' }).click();
    await sections(page).getByRole('link', { name: 'Status' }).click();
    await expect(page.getByRole('dialog')).toBeVisible();
    await axeCheck(page, info, 'Duet message box', FAILING);

    await go(page, '/m/demo-xtool/simulator');
    await expect(page.getByTestId('machine-link')).toHaveText('Online');
    await page.getByRole('button', { name: 'Flame under the laser' }).click();
    await expect(page.getByRole('alertdialog', { name: 'Critical alarm' })).toBeVisible();
    await axeCheck(page, info, 'blocking alarm', FAILING);
  });
});
