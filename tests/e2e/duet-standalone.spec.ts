import { mkdtempSync, rmSync, writeFileSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import { expect, test, type Page } from '@playwright/test';
import { Children, freePort, waitFor } from './own-server';

/**
 * Issue 20: a Duet WITHOUT a single-board computer (standalone RepRapFirmware, the `rr_*` API),
 * on the same Duet pages as DSF (duet.spec.ts). Its own console (open mode) with one simulated
 * standalone Duet (`"api": "standalone"`): the simulator runs in the console's server and speaks
 * only `rr_*` (8 sessions, 8 s timeout, X-Session-Key), the gateway holds the session.
 */

const ID = 'sa-duet';
const children = new Children();
let dir = '';
let base = '';

test.describe.configure({ mode: 'serial' });

async function tab(page: Page, name: string): Promise<void> {
  await page
    .getByRole('navigation', { name: 'Machine sections' })
    .getByRole('link', { name, exact: true })
    .tap();
}

test.describe('Duet standalone (rr_*)', () => {
  test.beforeAll(async ({}, info) => {
    if (info.project.name !== 'tablet') return;
    dir = mkdtempSync(join(tmpdir(), 'shopdeck-rrf-'));
    writeFileSync(
      join(dir, 'machines.json'),
      JSON.stringify({
        machines: [
          {
            id: ID,
            name: 'Printer bay — Duet 2 (standalone)',
            kind: 'duet',
            simulated: true,
            api: 'standalone',
          },
        ],
      }),
    );
    const port = await freePort();
    base = `http://127.0.0.1:${port}`;
    children.start(['--import', 'tsx', 'server/main.ts', '--port', String(port), '--host', '127.0.0.1'], {
      SHOPDECK_MACHINES: join(dir, 'machines.json'),
      SHOPDECK_USERS: join(dir, 'users.json'), // none: open mode
      SHOPDECK_DATA: join(dir, 'data'),
    });
    await waitFor(`${base}/api/machines`, 'the console');
  });

  test.afterAll(() => {
    children.stopAll();
    if (dir) rmSync(dir, { recursive: true, force: true });
  });

  test.beforeEach(({}, info) => {
    test.skip(info.project.name !== 'tablet', 'tablet layout only: it starts its own console');
  });

  test('prints, pauses and answers a message box like the DSF one', async ({ page }) => {
    await page.goto(`${base}/m/${ID}/files`);
    await expect(page.getByTestId('machine-link')).toHaveText('Online');
    await expect(page.getByTestId('simulated-banner')).toBeVisible();
    // rr_filelist, then rr_fileinfo with the thumbnail read by rr_thumbnail pages.
    const row = page.locator('[data-testid="duet-file-row"][data-name="bracket.gcode"]');
    await expect(row).toBeVisible();
    await expect(row.locator('img[data-format="png"]')).toBeVisible();

    await page.getByTestId('duet-start-bracket.gcode').tap();
    await expect(page.getByTestId('confirm-dialog')).toContainText('Start printing bracket.gcode?');
    await page.getByTestId('confirm-yes').tap();

    await tab(page, 'Status');
    await expect(page.getByTestId('duet-status')).toHaveText('Printing');
    await expect(page.getByTestId('duet-job-name')).toHaveText('bracket.gcode');
    await page.getByTestId('cmd-duet.pause').tap();
    await expect(page.getByTestId('duet-status')).toHaveText('Paused');

    // A message box (the board's M291), answered from the page: M292 by rr_gcode.
    await tab(page, 'Simulator');
    await page.getByTestId('sim-control-box-4').tap();
    await tab(page, 'Status');
    const dialog = page.getByTestId('duet-messagebox');
    await expect(dialog).toContainText('Which filament is loaded?');
    await page.getByTestId('duet-choice-1').tap();
    await page.getByTestId('duet-messagebox-ok').tap();
    await expect(dialog).toHaveCount(0);

    await page.getByTestId('cmd-duet.resume').tap();
    await expect(page.getByTestId('confirm-dialog')).toContainText('Resume the print?');
    await page.getByTestId('confirm-yes').tap();
    await expect(page.getByTestId('duet-status')).toHaveText('Printing');

    // The console: a code by rr_gcode, its reply by rr_reply.
    await tab(page, 'Console');
    await page.getByTestId('duet-console-input').fill('M115');
    await page.getByTestId('duet-console-send').tap();
    await expect(page.getByTestId('duet-console-log')).toContainText('FIRMWARE_NAME');
  });
});
