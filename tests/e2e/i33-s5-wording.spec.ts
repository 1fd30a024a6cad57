import { expect, test, type Page } from '@playwright/test';
import { resetSimulators } from './simulators';

/**
 * Issue 33, item 13: developer and protocol words do not reach the people at the machines. The
 * pages concerned (the audit log, TouchCut's monitor, Prunt's config form, the machine pages whose
 * errors and states come through src/fleet) are visited at tablet size; none shows a listed
 * developer string, and Prunt's unbounded limits read "no limit".
 */

const DEVELOPER_WORDS = [
  'Failed to fetch',
  'log in first',
  'ok:WORKING_ONLINE',
  'mfoe = 0',
  'axisLong',
  'axisShort',
  '1e+100',
  '-1e+100',
  '1E+100',
  'started started',
  'added added',
];

function section(page: Page, name: string) {
  return page.getByRole('navigation', { name: 'Machine sections' }).getByRole('link', { name, exact: true });
}

async function expectNoDeveloperWords(page: Page, where: string): Promise<void> {
  // The text and what the fields hold (a number field showed Prunt's 1E100 as "1e+100").
  const values = await page
    .locator('input[type="text"], input:not([type])')
    .evaluateAll((els) => els.map((e) => (e as HTMLInputElement).value));
  const text = `${await page.locator('body').innerText()}\n${values.join('\n')}`;
  const found = DEVELOPER_WORDS.filter((w) => text.includes(w));
  expect(found, `developer words on ${where}`).toEqual([]);
}

test('no developer or protocol words on the pages concerned; "no limit" for unbounded limits', async ({
  page,
  request,
}, info) => {
  test.skip(info.project.name !== 'tablet', 'tablet size (1024×768 touch)');
  test.setTimeout(120_000);
  await resetSimulators(request, ['demo-prunt', 'demo-touchcut']);

  // Prunt's config form: unbounded limits say "no limit".
  await page.goto('/m/demo-prunt');
  await expect(page.getByTestId('machine-link')).toHaveText('Online');
  await section(page, 'Config').click();
  await page
    .getByRole('button', { name: 'Steppers', exact: true })
    .or(page.getByRole('tab', { name: 'Steppers', exact: true }))
    .first()
    .click();
  await expect(page.getByText(/no (upper )?limit/).first()).toBeVisible();
  await expect(page.getByTestId('field-Steppers$Steppers$STEPPER_1$THIGH')).toHaveValue('no limit');
  await expectNoDeveloperWords(page, 'Prunt config');

  // TouchCut's monitor: the axes by name.
  await page.goto('/m/demo-touchcut/monitor');
  await expect(page.getByTestId('touchcut-axes')).toBeVisible();
  await expect(page.getByTestId('touchcut-axes')).toContainText('Long axis');
  await expectNoDeveloperWords(page, 'TouchCut monitor');

  // The xTool's socket frame and g2core's override rows in words.
  for (const id of ['demo-xtool', 'demo-g2core']) {
    await page.goto(`/m/${id}`);
    await expect(page.getByTestId('machine-link')).toHaveText('Online');
    await expectNoDeveloperWords(page, id);
  }

  // The audit log: machines by name, no "started started".
  await page.goto('/audit');
  await expect(page.getByTestId('audit-table')).toBeVisible();
  await expect(page.getByTestId('audit-table')).toContainText('Printer bay — Prunt');
  await expectNoDeveloperWords(page, 'the audit log');
  await page.screenshot({ path: '/tmp/s5-audit.png' });
});
