import { expect, test, type Page } from '@playwright/test';
import { resetSimulators } from './simulators';

/**
 * Duet (DSF) on the tablet layout, against the simulated printer `demo-duet` (its simulator runs
 * in the console's server; the Simulator tab drives it through `/api/sim/<id>`).
 */

const ID = 'demo-duet';

/** Opens a section of the machine page by its link in the "Machine sections" navigation. */
async function tab(page: Page, name: string): Promise<void> {
  await page
    .getByRole('navigation', { name: 'Machine sections' })
    .getByRole('link', { name, exact: true })
    .tap();
}

async function simControl(page: Page, control: string): Promise<void> {
  await tab(page, 'Simulator');
  await page.getByTestId(`sim-control-${control}`).tap();
}

test.describe('Duet (DSF)', () => {
  test.beforeEach(({}, info) => {
    test.skip(info.project.name !== 'tablet', 'tablet layout only');
  });
  // The simulators run in the server for the whole run: each test starts from a fresh world.
  test.beforeEach(async ({ request }) => {
    await resetSimulators(request, [ID]);
  });

  test('start, pause and cancel a simulated print', async ({ page }) => {
    await page.goto(`/m/${ID}/files`);
    await expect(page.getByTestId('machine-link')).toHaveText('Online');
    await expect(page.getByTestId('simulated-banner')).toBeVisible();
    const row = page.locator('[data-testid="duet-file-row"][data-name="bracket.gcode"]');
    await expect(row).toBeVisible();
    await expect(row.locator('img[data-format="png"]')).toBeVisible();

    // Start asks first; every row action is a touch-sized target.
    for (const b of await row.getByRole('button').all()) {
      expect((await b.boundingBox())?.height ?? 0).toBeGreaterThanOrEqual(44);
    }
    await page.getByTestId('duet-start-bracket.gcode').tap();
    await expect(page.getByTestId('confirm-dialog')).toContainText('Start printing bracket.gcode?');
    await page.getByTestId('confirm-yes').tap();

    await tab(page, 'Status');
    await expect(page.getByTestId('duet-status')).toHaveText('Printing');
    await expect(page.getByTestId('duet-job-name')).toHaveText('bracket.gcode');
    // Stop job (cancel) is only for a paused print: faint, its reason said.
    await expect(page.getByTestId('cmd-duet.cancel')).toHaveAttribute('aria-disabled', 'true');
    await expect(page.getByTestId('cmd-reason-duet.cancel')).toContainText('Pause the print first');

    // Pause: one tap, no confirmation, a big touch target.
    const pause = page.getByTestId('cmd-duet.pause');
    const box = await pause.boundingBox();
    expect(box?.height ?? 0).toBeGreaterThanOrEqual(44);
    await pause.tap();
    await expect(page.getByTestId('duet-status')).toHaveText('Paused');
    await expect(page.getByTestId('machine-activity')).toBeVisible();

    await page.getByTestId('cmd-duet.cancel').tap();
    await expect(page.getByTestId('confirm-dialog')).toContainText('Cancel the print?');
    await page.getByTestId('confirm-yes').tap();
    await expect(page.getByTestId('duet-status')).toHaveText('Idle');
    await expect(page.getByTestId('duet-job')).toContainText('Last: bracket.gcode');

    // The controller's messages are in the console with their levels.
    await tab(page, 'Console');
    await expect(page.getByTestId('duet-console-log')).toContainText(
      'Cancelled printing file 0:/gcodes/bracket.gcode',
    );
  });

  test('file list shows PNG, JPEG and QOI thumbnails', async ({ page }) => {
    await page.goto(`/m/${ID}/files`);
    await expect(page.getByTestId('machine-link')).toHaveText('Online');
    await expect(page.locator('img[data-format="png"]')).toBeVisible();
    await expect(page.locator('img[data-format="jpeg"]')).toBeVisible();
    await page.getByRole('button', { name: 'enclosure' }).tap();
    await expect(page.getByTestId('duet-dir')).toHaveText('0:/gcodes/enclosure');
    const qoi = page.locator('canvas[data-format="qoi"]');
    await expect(qoi).toBeVisible();
    // decoded, not blank: the centre pixel is the yellow of the triangle
    const centre = await qoi.evaluate((c: HTMLCanvasElement) =>
      Array.from(c.getContext('2d')!.getImageData(24, 30, 1, 1).data),
    );
    expect(centre).toEqual([233, 196, 106, 255]);
  });

  test('answers a message box from any page', async ({ page }) => {
    await page.goto(`/m/${ID}`);
    await expect(page.getByTestId('machine-link')).toHaveText('Online');
    await simControl(page, 'box-4');
    await tab(page, 'Status');
    const dialog = page.getByTestId('duet-messagebox');
    await expect(dialog).toContainText('Which filament is loaded?');
    await page.getByTestId('duet-choice-1').tap();
    await page.getByTestId('duet-messagebox-ok').tap();
    await expect(dialog).toHaveCount(0);

    await simControl(page, 'box-5');
    await tab(page, 'Files');
    await expect(dialog).toContainText('How many copies?');
    await page.getByTestId('duet-messagebox-input').fill('12');
    await expect(dialog).toContainText('At most 10');
    await page.getByTestId('duet-messagebox-input').fill('2');
    await page.getByTestId('duet-messagebox-ok').tap();
    await expect(dialog).toHaveCount(0);
  });

  test('the socket dies and the console reconnects without losing its history', async ({ page }) => {
    await page.goto(`/m/${ID}/console`);
    await expect(page.getByTestId('machine-link')).toHaveText('Online');
    await page.getByTestId('duet-console-input').fill('M115');
    await page.getByTestId('duet-console-send').tap();
    const log = page.getByTestId('duet-console-log');
    await expect(log).toContainText('FIRMWARE_NAME');

    // The DSF service goes away (socket close 1011), then comes back.
    await simControl(page, 'dcs-down');
    await expect(page.getByTestId('link-problem')).toContainText('(DSF) or the link to it is down');
    await expect(page.getByTestId('machine-link')).toHaveText('Online', { timeout: 30_000 });

    await tab(page, 'Console');
    await expect(log).toContainText('FIRMWARE_NAME');
    await expect(log).toContainText('> M115');
    // Emergency stop is on this page too.
    await expect(page.getByTestId('cmd-duet.estop')).toBeVisible();
  });
});
