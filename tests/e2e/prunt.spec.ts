import { expect, test, type Page } from '@playwright/test';
import { resetSimulators } from './simulators';

/**
 * Prunt config editor against the simulated board `demo-prunt` (module API; its simulator runs in
 * the console's server).
 * A supervisor changes a stepper current on its tab, reviews, saves, sees the controller's error
 * under that field, fixes it, saves again and reloads the server to apply.
 */

const ID = 'demo-prunt';

/** A section of the machine page: a link in the "Machine sections" navigation. */
function section(page: Page, name: string) {
  return page.getByRole('navigation', { name: 'Machine sections' }).getByRole('link', { name, exact: true });
}
const FIELD = 'Steppers$Steppers$STEPPER_1$Run current';

test.describe('Prunt config editor', () => {
  // The simulators run in the server for the whole run: each test starts from a fresh world.
  test.beforeEach(async ({ request }) => {
    await resetSimulators(request, [ID]);
  });

  test('a supervisor edits a stepper current, sees the server error, fixes it and reloads the server', async ({
    page,
  }) => {
    await page.goto(`/m/${ID}`);
    await expect(page.getByTestId('machine-link')).toHaveText('Online');
    await section(page, 'Config').click();
    await expect(page.getByTestId('form-view')).toBeVisible();

    await page.getByTestId('section-Steppers').click();
    await page.getByTestId('ftab-Steppers$Steppers$STEPPER_1').click();
    const input = page.getByTestId(`field-${FIELD}`);
    await expect(input).toHaveValue('1.2');

    // Out of the schema's range: refused as you type, badges on the tab and the section.
    await input.fill('3.5');
    await expect(page.getByTestId(`local-error-${FIELD}`)).toContainText('Out of range');
    await expect(page.getByTestId('section-Steppers')).toContainText('1');

    // Within the schema, but too much for the motor: the controller says so after the save.
    await input.fill('3');
    await expect(page.getByTestId(`local-error-${FIELD}`)).toHaveCount(0);
    await page.getByTestId('prunt-review').click();
    const review = page.getByTestId('review-dialog');
    await expect(review).toContainText('Steppers › STEPPER_1 › Run current');
    await expect(review).toContainText('1.2');
    await review.getByTestId('cmd-prunt.saveConfig').click();
    await expect(page.getByTestId('prunt-save-result')).toContainText('Saved');
    await expect(page.getByTestId(`server-error-${FIELD}`)).toContainText('overheat');

    // Fix it and save again: the error goes away.
    await input.fill('2');
    await page.getByTestId('prunt-review').click();
    await page.getByTestId('review-dialog').getByTestId('cmd-prunt.saveConfig').click();
    await expect(page.getByTestId(`server-error-${FIELD}`)).toHaveCount(0);
    await expect(input).toHaveValue('2');

    // Reload the server to apply: confirmed, then the console reconnects and refetches.
    await page.getByTestId('prunt-offer-reload').getByTestId('cmd-prunt.reloadServer').click();
    await expect(page.getByTestId('confirm-dialog')).toContainText('Reload the Prunt server');
    await page.getByTestId('confirm-yes').click();
    await expect(page.getByText('The server restarted: schema and values were fetched again.')).toBeVisible();
    await expect(page.getByTestId('machine-link')).toHaveText('Online');
    await expect(page.getByTestId(`field-${FIELD}`)).toHaveValue('2');
  });

  test('status, files and the G-code console', async ({ page }, info) => {
    test.skip(info.project.name !== 'desktop', 'desktop layout only');
    await page.goto(`/m/${ID}`);
    await expect(page.getByTestId('machine-link')).toHaveText('Online');
    await section(page, 'Readings').click();
    await expect(page.getByTestId('prunt-status')).toContainText('Internal Status Reporter');
    await expect(page.getByTestId('prunt-status')).toContainText(
      'Only present when the thermistor kind is not Disabled.',
    );
    await section(page, 'Console').click();
    await page.getByTestId('prunt-gcode-input').fill('M114');
    await page.getByTestId('prunt-gcode-input').press('Enter');
    await expect(page.getByTestId('prunt-gcode-history')).toContainText('Completed');
    await expect(page.getByTestId('prunt-gcode-history')).toContainText('X:117.500');
    await section(page, 'Files').click();
    await expect(page.getByTestId('prunt-files')).toContainText('benchy.gcode');
    await page.getByTestId('run-benchy.gcode').click();
    await page.getByTestId('confirm-yes').click();
    await expect(page.getByTestId('machine-activity')).toContainText(/running/i);
    await expect(page.getByTestId('run-calibration_cube.gcode')).toBeDisabled();
    // The controller's own 500 text is shown as it is, next to the action.
    await section(page, 'Console').click();
    await page.getByTestId('prunt-gcode-input').fill('G28');
    await page.getByTestId('prunt-gcode-input').press('Enter');
    await expect(page.getByTestId('prunt-gcode-error')).toHaveText(
      'Can not run command while a file is running.',
    );
  });
});
