import { expect, test, type Page } from '@playwright/test';
import { resetSimulators, simulator } from './simulators';

/**
 * xTool D-series on the tablet layout, against the simulated laser `demo-xtool` (its simulator
 * runs in the console's server). The simulator's controls stand in for the physical world:
 * loading a job as the vendor app would, the machine's button, a flame under the laser. A
 * supervisor has them on the Simulator tab; for the operator the test drives them through the
 * gateway (`/api/sim/<id>`), as someone at the machine would.
 */

const ID = 'demo-xtool';

/** A section of the machine page: a link in the "Machine sections" navigation. */
function section(page: Page, name: string) {
  return page.getByRole('navigation', { name: 'Machine sections' }).getByRole('link', { name, exact: true });
}

/** Act as an operator: the console asks the gateway who we are (`/api/session`). */
async function asOperator(page: Page): Promise<void> {
  await page.route('**/api/session', (route) =>
    route.fulfill({
      contentType: 'application/json',
      body: JSON.stringify({ mode: 'secured', user: { name: 'olga', role: 'operator', machines: null } }),
    }),
  );
}

test.describe('xTool D-series', () => {
  test.beforeEach(({}, info) => {
    test.skip(info.project.name !== 'tablet', 'tablet layout only');
  });
  // The simulators run in the server for the whole run: each test starts from a fresh world.
  test.beforeEach(async ({ request }) => {
    await resetSimulators(request, [ID]);
  });

  test('an operator pauses and resumes a simulated job', async ({ page, request }) => {
    await asOperator(page);
    await page.goto(`/m/${ID}`);
    await expect(page.getByTestId('machine-link')).toHaveText('Online');
    // Operators see job controls but not the supervisor tabs, nor the simulator's.
    await expect(section(page, 'Console')).toHaveCount(0);
    await expect(section(page, 'Firmware')).toHaveCount(0);
    await expect(section(page, 'Simulator')).toHaveCount(0);

    await simulator(request, ID, 'world', 'load-job');
    await section(page, 'Status').click();
    await expect(page.getByTestId('xtool-press-button')).toBeVisible();
    await expect(page.getByTestId('machine-label')).toContainText('press the button on the machine');

    await simulator(request, ID, 'world', 'button');
    await section(page, 'Status').click();
    await expect(page.getByTestId('xtool-state')).toHaveText('running');

    // Pause: no confirmation, a big touch target.
    const pause = page.getByTestId('cmd-xtool.pause');
    await expect(pause).toBeEnabled();
    const box = await pause.boundingBox();
    expect(box?.height ?? 0).toBeGreaterThanOrEqual(44);
    await pause.tap();
    await expect(page.getByTestId('xtool-state')).toHaveText('paused');

    // Resume asks first.
    await page.getByTestId('cmd-xtool.resume').tap();
    await expect(page.getByTestId('confirm-dialog')).toContainText('Resume the job?');
    await page.getByTestId('confirm-yes').tap();
    await expect(page.getByTestId('xtool-state')).toHaveText('running');
    await expect(page.getByTestId('cmd-xtool.pause')).toBeEnabled();
  });

  test('a flame alarm blocks every page until acknowledged', async ({ page }) => {
    await page.goto(`/m/${ID}/simulator`);
    await expect(page.getByTestId('machine-link')).toHaveText('Online');
    await page.getByTestId('sim-control-flame').click();
    const alarm = page.getByTestId('blocking-alarm');
    await expect(alarm).toBeVisible();
    await expect(alarm).toContainText('FLAME DETECTED');

    // Another page of the console (in-app navigation; a reload would show the alarm too).
    await page.evaluate(() => {
      history.pushState(null, '', '/');
      window.dispatchEvent(new PopStateEvent('popstate'));
    });
    await expect(page).toHaveURL(/\/$/);
    await expect(alarm).toBeVisible();
    // The rest of the page is blocked: inert, and clicks land on the alarm's backdrop, not the tiles.
    await expect(alarm).toHaveRole('alertdialog');
    await expect(page.getByTestId('app-page')).toHaveAttribute('inert', '');
    await expect(page.getByTestId('tile-demo-duet')).toBeVisible();
    await page
      .getByTestId('tile-demo-duet')
      .locator('a')
      .click({ trial: true, timeout: 2000 })
      .then(
        () => {
          throw new Error('the fleet was clickable under a blocking alarm');
        },
        () => undefined,
      );

    await page.getByTestId(`ack-${ID}`).click();
    await expect(alarm).toBeHidden();
    await page.getByRole('link', { name: 'Printer bay — Duet 3' }).click();
    await expect(page).toHaveURL(/\/m\/demo-duet$/);
  });
});
