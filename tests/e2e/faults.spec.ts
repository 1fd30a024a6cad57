import { expect, test } from '@playwright/test';
import { resetSimulators } from './simulators';

/**
 * Issue 15 as an operator sees it: a controller that stops answering shows as down, in
 * words (never a JSON dump, never a model verdict), says when it tries again, and comes back by
 * itself when the controller answers again — no reload.
 */
test.describe('faults', () => {
  test.beforeEach(async ({ request }) => {
    await resetSimulators(request);
  });

  for (const id of ['demo-xtool', 'demo-g2core'] as const) {
    test(`${id}: a controller that stops answering is reconnecting, in words, and back by itself`, async ({
      page,
    }) => {
      await page.goto(`/m/${id}/simulator`);
      await expect(page.getByTestId('machine-link')).toHaveText('Online');
      await page.getByTestId('fault-drop').check();
      await page.getByTestId('fault-close-sockets').click();
      // Reconnecting, or offline (an xTool with neither HTTP nor its socket looks switched off).
      await expect(page.getByTestId('machine-link')).toHaveText(/^(Reconnecting|Offline)$/, {
        timeout: 15_000,
      });
      const problem = page.getByTestId('link-problem');
      await expect(problem).toBeVisible();
      await expect(problem).toContainText(/next try in \d+ s/);
      const words = (await problem.textContent()) ?? '';
      expect(words).not.toMatch(/[{[]\s*"/);
      expect(words).not.toMatch(/unsupported|incompatible|protocol/i);

      await page.getByTestId('fault-drop').uncheck();
      await expect(page.getByTestId('machine-link')).toHaveText('Online', { timeout: 15_000 });
      await expect(page.getByTestId('link-problem')).toHaveCount(0);
    });
  }
});
