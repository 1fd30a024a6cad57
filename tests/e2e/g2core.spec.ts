import { expect, test, type Page } from '@playwright/test';
import { resetSimulators } from './simulators';

/**
 * g2core CNC over the REST design, against the simulated router `demo-g2core` (its simulator runs
 * in the console's server). Everything the machine says here is simulated.
 */

const ID = 'demo-g2core';

/** A section of the machine page: a link in the "Machine sections" navigation. */
function section(page: Page, name: string) {
  return page.getByRole('navigation', { name: 'Machine sections' }).getByRole('link', { name, exact: true });
}

async function asRole(page: Page, role: 'operator' | 'supervisor'): Promise<void> {
  await page.route('**/api/session', (route) =>
    route.fulfill({
      contentType: 'application/json',
      body: JSON.stringify({
        mode: 'secured',
        user: { name: role === 'operator' ? 'olga' : 'sam', role, machines: null },
      }),
    }),
  );
}

/** Ten 10 mm moves at 300 mm/min: about 20 s of motion, long enough to hold and resume. */
const JOB = ['G21 G90', ...Array.from({ length: 10 }, (_, i) => `G1 X${(i + 1) * 10} F300`)].join('\n');

test.describe('g2core', () => {
  // The simulators run in the server for the whole run: each test starts from a fresh world.
  test.beforeEach(async ({ request }) => {
    await resetSimulators(request, [ID]);
  });

  test('an operator runs a small job, holds, resumes and kills it', async ({ page }, info) => {
    test.skip(info.project.name !== 'tablet', 'tablet layout');
    await asRole(page, 'operator');
    await page.goto(`/m/${ID}/jobs`);
    await expect(page.getByTestId('machine-link')).toHaveText('Online');
    // Operators do not see the supervisor tabs.
    await expect(section(page, 'Settings')).toHaveCount(0);
    await expect(section(page, 'Console')).toHaveCount(0);

    await page.getByTestId('g2-job-name').fill('bar.nc');
    await page.getByTestId('g2-job-gcode').fill(JOB);
    await page.getByTestId('g2-job-queue-text').tap();
    await expect(page.getByTestId('g2-job-name-1')).toHaveText('bar.nc');

    await page.getByTestId('g2-job-run-1').tap();
    await expect(page.getByTestId('confirm-dialog')).toContainText('Start job "bar.nc"?');
    await page.getByTestId('confirm-yes').tap();
    await expect(page.getByTestId('g2-stat')).toHaveText('Run');
    await expect(page.getByTestId('g2-job-lines')).toContainText('/ 11 lines');

    // Feedhold: no confirmation, a big touch target.
    const hold = page.getByTestId('cmd-g2core.feedhold').first();
    const box = await hold.boundingBox();
    expect(box?.height ?? 0).toBeGreaterThanOrEqual(44);
    await hold.tap();
    await expect(page.getByTestId('g2-stat')).toHaveText('Hold');
    await expect(page.getByTestId('g2-job-state-1')).toHaveText('paused');

    // Cycle start asks first.
    await page.getByTestId('cmd-g2core.resume').first().tap();
    await expect(page.getByTestId('confirm-dialog')).toContainText('resume motion');
    await page.getByTestId('confirm-yes').tap();
    await expect(page.getByTestId('g2-stat')).toHaveText('Run');

    // Kill asks, then the job is abandoned and the machine ends (stat 4).
    await page.getByTestId('cmd-g2core.kill').first().tap();
    await expect(page.getByTestId('confirm-dialog')).toContainText('Kill');
    await page.getByTestId('confirm-yes').tap();
    await expect(page.getByTestId('g2-stat')).toHaveText('End');
    await expect(page.getByTestId('g2-job-state-1')).toHaveText('killed');
  });

  test('a supervisor changes X max velocity and sees a refused read-only key', async ({ page }, info) => {
    test.skip(info.project.name !== 'desktop', 'desktop layout');
    await asRole(page, 'supervisor');
    await page.goto(`/m/${ID}/settings`);
    await expect(page.getByTestId('machine-link')).toHaveText('Online');

    await page.getByTestId('g2-group-x').click();
    const vm = page.getByTestId('g2-input-x-vm');
    await expect(vm).toHaveValue('40000');
    await vm.fill('30000');
    await page.getByTestId('g2-save-x.vm').click();
    await expect(page.getByTestId('g2-field-x.vm')).toContainText('saved');
    await page.getByRole('button', { name: 'Reload' }).click();
    await expect(page.getByTestId('g2-input-x-vm')).toHaveValue('30000');

    // Identity keys are shown read-only from the start.
    await page.getByTestId('g2-group-sys').click();
    await expect(page.getByTestId('g2-readonly-sys.fb')).toBeVisible();

    // G92 offsets are set by G-code: the controller refuses the edit with its status text.
    await page.getByTestId('g2-group-g92').click();
    await page.getByTestId('g2-input-g92-x').fill('5');
    await page.getByTestId('g2-save-g92.x').click();
    await expect(page.getByTestId('g2-error-g92.x')).toContainText('Parameter is read-only');
    await expect(page.getByTestId('g2-readonly-g92.x')).toBeVisible();
  });
});
