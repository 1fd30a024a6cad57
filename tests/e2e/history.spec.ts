import AxeBuilder from '@axe-core/playwright';
import { expect, test, type APIRequestContext } from '@playwright/test';
import { resetSimulators, simulator } from './simulators';

/**
 * The production history (issue 18): the server records what the machines do whether or not a
 * page is open. A simulated laser runs a job with no page open; the History page then shows it
 * (the jobs table and the machine's timeline strip) and its CSV export answers text/csv.
 */

const ID = 'demo-xtool';
const NAME = 'Laser bay — xTool D1 Pro';

interface JobRow {
  id: number;
  machine: string;
  name: string | null;
  startedAt: number;
  outcome: string | null;
}

async function jobsOf(request: APIRequestContext, extra = ''): Promise<JobRow[]> {
  const r = await request.get(`/api/history/jobs?machine=${ID}${extra}`);
  expect(r.status()).toBe(200);
  return ((await r.json()) as { jobs: JobRow[] }).jobs;
}

test('the History page shows a job that ran while no page was open', async ({ page, request }, info) => {
  test.setTimeout(120_000);
  await resetSimulators(request, [ID]);
  // A job of an earlier test closes once the watch sees the laser idle after the reset.
  await expect.poll(async () => (await jobsOf(request, '&outcome=open')).length, { timeout: 40_000 }).toBe(0);
  const t0 = Date.now();
  await simulator(request, ID, 'world', 'demo');
  // Recorded by the server: no page is open yet.
  let job: JobRow | undefined;
  await expect
    .poll(
      async () => {
        job = (await jobsOf(request)).find((j) => j.startedAt >= t0 - 2000);
        return job !== undefined;
      },
      { timeout: 60_000, intervals: [1000] },
    )
    .toBe(true);
  if (!job) throw new Error('no job');

  await page.goto('/history');
  await expect(page.getByTestId('history-page')).toBeVisible();
  const row = page.getByTestId('history-jobs-table').locator('tbody tr').filter({ hasText: NAME }).first();
  await expect(row).toBeVisible();
  await expect(row).toContainText(job.name ?? '(no name)');
  await expect(row).toContainText(job.outcome ?? 'running now');

  const strip = page.getByTestId(`history-strip-${ID}`);
  await expect(strip).toContainText(NAME);
  await expect(strip.locator('rect[data-state="running"]').first()).toBeAttached();
  await expect(page.getByTestId(`history-util-${ID}`)).toBeVisible();

  // The CSV link the page offers answers a CSV (the session cookie goes along in a browser).
  const href = await page.getByTestId('history-jobs-csv').getAttribute('href');
  expect(href).toMatch(/^\/api\/history\/jobs\.csv\?/);
  const csv = await request.get(href ?? '');
  expect(csv.status()).toBe(200);
  expect(csv.headers()['content-type']).toMatch(/^text\/csv/);
  const text = await csv.text();
  expect(text).toContain('id,machine,machine_name,family,job,started');
  expect(text).toContain(`${job.id},${ID},`);

  await page.screenshot({ path: info.outputPath(`history-${info.project.name}.png`), fullPage: true });
  if (info.project.name === 'desktop') {
    await page.setViewportSize({ width: 390, height: 844 });
    await expect(strip.locator('rect[data-state="running"]').first()).toBeAttached();
    await page.screenshot({ path: info.outputPath('history-phone.png'), fullPage: true });
  }
});

test('the History page has no serious accessibility problem (axe, light and dark)', async ({ page }) => {
  // Two axe runs over a long page: CPU-bound, slow on a busy 2-core machine.
  test.slow();
  await page.goto('/');
  await page.getByRole('navigation', { name: 'Main' }).getByRole('link', { name: 'History' }).click();
  await expect(page).toHaveURL(/\/history$/);
  await expect(page.getByTestId(`history-strip-${ID}`)).toBeVisible();
  await expect(page.getByTestId('history-settings')).toBeVisible();
  for (const scheme of ['light', 'dark'] as const) {
    await page.emulateMedia({ colorScheme: scheme });
    const results = await new AxeBuilder({ page })
      .withTags(['wcag2a', 'wcag2aa', 'wcag21a', 'wcag21aa', 'wcag22aa', 'best-practice'])
      .analyze();
    const bad = results.violations
      .filter((v) => v.impact === 'serious' || v.impact === 'critical')
      .map(
        (v) =>
          `${v.id}: ${v.nodes
            .map((n) => n.target.join(' '))
            .slice(0, 3)
            .join(' | ')}`,
      );
    expect.soft(bad, `${scheme} theme`).toEqual([]);
  }
});
