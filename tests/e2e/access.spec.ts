import { mkdtempSync, readFileSync, rmSync, writeFileSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import { expect, test, type Browser, type Page } from '@playwright/test';
import { Children, freePort, signIn as signInAs, waitFor, writeUsersFile } from './own-server';

/**
 * Access control end to end, through the real gateway (vite preview) with a users file, against
 * the xTool simulator served as hardware by `npm run sim` (so every request crosses the gateway
 * to a real server, as to a laser on the network):
 * a viewer sees a running job but has no controls, and a crafted request is refused by the
 * gateway; an operator pauses; a supervisor edits a setting; the audit page shows all three.
 */

const USERS = {
  vera: { role: 'viewer', password: 'viewer-password-1' },
  otto: { role: 'operator', password: 'operator-password-1' },
  sam: { role: 'supervisor', password: 'supervisor-password-1' },
} as const;
const ID = 'sim-xtool';

let dir = '';
let base = '';
let simUrl = '';
const children = new Children();

test.describe.configure({ mode: 'serial' });

test.describe('access control', () => {
  test.beforeAll(async ({}, info) => {
    if (info.project.name !== 'desktop') return;
    dir = mkdtempSync(join(tmpdir(), 'shopdeck-access-'));
    const simFile = join(dir, 'sim-machines.json');
    children.start(['--import', 'tsx', 'scripts/sim.ts', '--write', simFile], {});
    for (let i = 0; i < 240 && !simUrl; i++) {
      try {
        const f = JSON.parse(readFileSync(simFile, 'utf8')) as {
          machines: Array<{ id: string; url: string }>;
        };
        const m = f.machines.find((x) => x.id === ID);
        if (m) simUrl = m.url;
        writeFileSync(
          join(dir, 'machines.json'),
          JSON.stringify({ machines: f.machines.filter((x) => x.id === ID) }),
        );
      } catch {
        await new Promise((r) => setTimeout(r, 250));
      }
    }
    if (!simUrl) throw new Error('npm run sim did not write its machines file');
    writeUsersFile(join(dir, 'users.json'), USERS);
    const port = await freePort();
    base = `http://127.0.0.1:${port}`;
    const outDir = process.env.SHOPDECK_E2E_OUTDIR ? ['--outDir', process.env.SHOPDECK_E2E_OUTDIR] : [];
    children.start(
      [
        'node_modules/vite/bin/vite.js',
        'preview',
        '--port',
        String(port),
        '--strictPort',
        '--host',
        '127.0.0.1',
        ...outDir,
      ],
      {
        SHOPDECK_MACHINES: join(dir, 'machines.json'),
        SHOPDECK_USERS: join(dir, 'users.json'),
        SHOPDECK_DATA: join(dir, 'data'),
      },
    );
    await waitFor(`${base}/api/session`, 'the gateway');
  });

  test.afterAll(() => {
    children.stopAll();
    if (dir) rmSync(dir, { recursive: true, force: true });
  });

  test.beforeEach(({}, info) => {
    test.skip(info.project.name !== 'desktop', 'one run is enough: it starts its own gateway');
  });

  /**
   * A fresh job on the machine: whatever ran is cancelled (holding the button), then a job is
   * loaded as the vendor app would and started with the button. It lasts about a minute.
   */
  async function startJob(): Promise<void> {
    const control = async (id: string) =>
      expect((await fetch(`${simUrl}/__sim/control/${id}`, { method: 'POST' })).status).toBe(200);
    await control('hold-button');
    await expect
      .poll(
        async () =>
          ((await (await fetch(`${simUrl}/system?action=get_working_sta`)).json()) as { working: string })
            .working,
      )
      .toBe('0');
    await control('load-job');
    await control('button');
  }

  const signIn = (browser: Browser, name: keyof typeof USERS): Promise<Page> =>
    signInAs(browser, base, name, USERS[name]);

  test('a viewer sees the running job but has no controls, and the gateway refuses a crafted request', async ({
    browser,
  }) => {
    const page = await signIn(browser, 'vera');
    await startJob();
    await page.goto(`/m/${ID}`);
    await expect(page.getByTestId('machine-link')).toHaveText('Online');
    await expect(page.getByTestId('xtool-state')).toHaveText('running');
    const pause = page.getByTestId('cmd-xtool.pause');
    if ((await pause.count()) > 0) await expect(pause).toBeDisabled();

    const crafted = await page.evaluate(async (id) => {
      const r = await fetch(`/machines/${id}/cnc/data?action=pause`, {
        // The viewer's own console page: it can send the console header, the role still counts.
        headers: { 'X-Shopdeck-Command': 'xtool.pause', 'X-Shopdeck': '1' },
      });
      return { status: r.status, body: (await r.json()) as { error: string; needs: string } };
    }, ID);
    expect(crafted.status).toBe(403);
    expect(crafted.body.needs).toBe('operator');
    await expect(page.getByTestId('xtool-state')).toHaveText('running');
    await page.context().close();
  });

  test('an operator pauses the job', async ({ browser }) => {
    const page = await signIn(browser, 'otto');
    await startJob();
    await page.goto(`/m/${ID}`);
    await expect(page.getByTestId('xtool-state')).toHaveText('running');
    await page.getByTestId('cmd-xtool.pause').click();
    await expect(page.getByTestId('xtool-state')).toHaveText('paused');
    // Settings stay out of reach: the gateway would refuse them too.
    const crafted = await page.evaluate(async (id) => {
      const r = await fetch(`/machines/${id}/system?action=setTiltCheckThreshold&value=9`);
      return r.status;
    }, ID);
    expect(crafted).toBe(403);
    await page.context().close();
  });

  test('a supervisor edits a setting, and the audit page shows all three', async ({ browser }) => {
    const page = await signIn(browser, 'sam');
    await page.goto(`/m/${ID}/safety`);
    await expect(page.getByTestId('machine-link')).toHaveText('Online');
    await page.getByLabel(/Tilt threshold/).fill('42');
    await page.getByTestId('cmd-xtool.tilt-threshold').click();
    await expect(page.getByLabel(/Tilt threshold \(now 42\)/)).toBeVisible();

    await page.goto('/audit');
    const table = page.getByTestId('audit-table');
    await expect(table).toBeVisible();
    await expect(
      table.getByRole('row').filter({ hasText: 'vera' }).filter({ hasText: 'refused' }),
    ).toHaveCount(1);
    await expect(
      table.getByRole('row').filter({ hasText: 'otto' }).filter({ hasText: 'xtool.pause' }),
    ).toHaveCount(1);
    await expect(
      table.getByRole('row').filter({ hasText: 'sam' }).filter({ hasText: 'xtool.tilt-threshold' }),
    ).toHaveCount(1);
    await page.getByLabel('Result').selectOption('refused');
    await page.getByRole('button', { name: 'Apply filters' }).click();
    await expect(table.getByRole('row')).toHaveCount(3); // header, vera's refused pause, otto's refused setting
    const csv = await page.getByRole('link', { name: 'Export CSV' }).getAttribute('href');
    expect(csv).toBe('/api/audit.csv?result=refused');
    await page.context().close();
  });
});
