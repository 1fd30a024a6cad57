import { expect, test, type Locator, type Page } from '@playwright/test';
import { resetSimulators, simulator } from './simulators';

/**
 * Issue 33 item 6: a job's facts are the same on every view. The tile, the wall (1920×1080),
 * the kiosk and the machine page show the same job name and the same percentage (one record,
 * the server's; one formatter, src/fleet/job-facts.ts), a progress bar says the percentage
 * written beside it, the running time survives a reload of the page, and a job at a known
 * progress has a time left. Tablet project (1024×768 touch), against the demo fleet's simulators.
 */

const WALL = { width: 1920, height: 1080 };
const TABLET = { width: 1024, height: 768 };

/** Whole percentages written in a text ("Printing 16 %" → [16]). */
function percents(text: string): number[] {
  return [...text.matchAll(/(\d+)\s?%/g)].map((m) => Number(m[1]));
}

/** "running for [at least ]1 h 02 min" / "3 min 05 s" / "12 s" in seconds. */
function runningSeconds(text: string): number {
  const m = /running for (?:at least )?(?:(\d+) h )?(?:(\d+) min)? ?(?:(\d+) s)?/.exec(text);
  if (!m || (m[1] === undefined && m[2] === undefined && m[3] === undefined))
    throw new Error(`not a running time: "${text}"`);
  return Number(m[1] ?? 0) * 3600 + Number(m[2] ?? 0) * 60 + Number(m[3] ?? 0);
}

/** The value a progress bar announces (aria-valuenow), as a number. */
async function barValue(bar: Locator): Promise<number> {
  await expect(bar).toHaveAttribute('aria-valuenow', /\d+/);
  return Number(await bar.getAttribute('aria-valuenow'));
}

/** The tile of a machine on the fleet page, once it shows a job with a percentage. */
async function tileJob(page: Page, id: string): Promise<{ name: string; percent: string }> {
  const tile = page.getByTestId(`tile-${id}`);
  await expect(tile.getByTestId('tile-job-percent')).toHaveText(/\d+\s?%/, { timeout: 30_000 });
  return {
    name: (await tile.getByTestId('tile-job-name').textContent()) ?? '',
    percent: (await tile.getByTestId('tile-job-percent').textContent()) ?? '',
  };
}

/**
 * The fleet page after the job was paused: waits until the tile's facts hold still for longer than
 * a change takes to reach a page (the server's watch reads every 5–10 s, the page asks it again
 * every 5 s: boot.ts), then returns them.
 */
async function settledTile(page: Page, id: string): Promise<{ name: string; percent: string }> {
  await page.setViewportSize(TABLET);
  await page.goto('/');
  let facts = await tileJob(page, id);
  await expect(async () => {
    const before = await tileJob(page, id);
    await page.waitForTimeout(16_000);
    facts = await tileJob(page, id);
    expect(facts).toEqual(before);
  }).toPass({ timeout: 90_000 });
  return facts;
}

/**
 * The same name and percentage on the tile, the wall, the kiosk and the machine page; each
 * progress bar says the percentage written beside it; the running time survives a reload.
 */
async function sameFactsEverywhere(page: Page, id: string, name: string | RegExp): Promise<void> {
  const tileFacts = await settledTile(page, id);
  expect(tileFacts.name).toMatch(name);
  expect(tileFacts.percent).toMatch(/\d+\s?%/);
  const pct = percents(tileFacts.percent)[0] ?? -1;
  const tile = page.getByTestId(`tile-${id}`);
  // The tile's bar and every percentage written on the tile (its state line too) are that one.
  expect(await barValue(tile.getByRole('progressbar'))).toBe(pct);
  const tileWords = `${await tile.getByTestId('tile-label').textContent()} ${await tile.getByTestId('tile-job').textContent()}`;
  for (const p of percents(tileWords)) expect(p).toBe(pct);

  // The wall, at its own size.
  await page.setViewportSize(WALL);
  await page.goto('/wall');
  const card = page.getByTestId(`wall-card-${id}`);
  await expect(card.getByTestId('wall-job-name')).toHaveText(tileFacts.name);
  await expect(card.getByTestId('wall-job-percent')).toHaveText(tileFacts.percent);
  expect(await barValue(card.getByRole('progressbar'))).toBe(pct);
  // Its state line (absent when the card shows an alarm instead) and its job.
  const wallWords = `${(await card.locator('.wall-label').allTextContents()).join(' ')} ${await card.getByTestId('wall-job').textContent()}`;
  for (const p of percents(wallWords)) expect(p).toBe(pct);

  // The kiosk (`/m/<id>?kiosk`), back on the tablet.
  await page.setViewportSize(TABLET);
  await page.goto(`/m/${id}?kiosk`);
  await expect(page.getByTestId('kiosk-job-name')).toHaveText(tileFacts.name);
  await expect(page.getByTestId('kiosk-progress')).toHaveText(tileFacts.percent);
  expect(await barValue(page.getByRole('progressbar', { name: 'Job progress' }).first())).toBe(pct);

  // The machine page: its job facts and its header.
  await page.goto(`/m/${id}`);
  const facts = page.getByTestId('job-facts');
  await expect(facts.getByTestId('job-facts-name')).toHaveText(tileFacts.name);
  await expect(facts.getByTestId('job-facts-percent')).toHaveText(tileFacts.percent);
  for (const p of percents((await page.getByTestId('machine-label').textContent()) ?? ''))
    expect(p).toBe(pct);

  // The running time is the server's: a reload does not restart it.
  const running = facts.getByTestId('job-facts-running');
  await expect(running).toHaveText(/running for/);
  const before = runningSeconds((await running.textContent()) ?? '');
  await page.reload();
  await expect(page.getByTestId('job-facts-running')).toHaveText(/running for/);
  const after = runningSeconds((await page.getByTestId('job-facts-running').textContent()) ?? '');
  expect(after).toBeGreaterThanOrEqual(before);
}

/** Waits (fleet page) until a machine shows no job: its next job is one the server sees start. */
async function noJob(page: Page, id: string): Promise<void> {
  await page.goto('/');
  await expect(page.getByTestId(`tile-${id}`).getByTestId('tile-job')).toHaveCount(0, { timeout: 20_000 });
}

test.describe('issue 33 item 6: job facts from one record', () => {
  test.beforeEach(({}, info) => {
    test.skip(
      info.project.name !== 'tablet',
      'tablet project (1024×768 touch), the wall at 1920×1080 inside',
    );
  });
  test.describe.configure({ timeout: 240_000 });

  test('TouchCut: the same job on every view, and its time left at a known progress', async ({
    page,
    request,
  }) => {
    const id = 'demo-touchcut';
    await resetSimulators(request, [id]);
    await noJob(page, id);
    await simulator(request, id, 'world', 'start');
    // Some way into the program, then a feed hold freezes its progress.
    await expect
      .poll(async () => percents((await tileJob(page, id)).percent)[0] ?? 0, { timeout: 60_000 })
      .toBeGreaterThanOrEqual(2);
    await simulator(request, id, 'world', 'pause');
    await sameFactsEverywhere(page, id, /\.nc$/);

    // At a known progress the time left is said (an estimate from the pace), never "—".
    await expect(page.getByTestId('job-facts-remaining')).toHaveText(/\d+ (s|min|h)\b.* left/);
    await page.goto(`/m/${id}?kiosk`);
    await expect(page.getByTestId('kiosk-remaining')).toHaveText(/\d/);
    await expect(page.getByTestId('kiosk-remaining')).not.toHaveText('—');
  });

  test('xTool: the job the laser names (tmp.gcode) is the same on the tile, the wall, the kiosk and its page', async ({
    page,
    request,
  }) => {
    const id = 'demo-xtool';
    await resetSimulators(request, [id]);
    await noJob(page, id);
    // The operator presses the button once the laser says the job is loaded (a laser still
    // stopping the last job ignores the load, and its button would run the card's file instead).
    await expect(async () => {
      await simulator(request, id, 'world', 'load-job');
      const r = await request.get('/api/machines');
      const { machines } = (await r.json()) as {
        machines: Array<{ id: string; watch?: { job: string | null } }>;
      };
      expect(machines.find((m) => m.id === id)?.watch?.job).toBe('tmp.gcode');
    }).toPass({ timeout: 20_000 });
    await simulator(request, id, 'world', 'button');
    await page.goto(`/m/${id}`);
    await expect(page.getByTestId('machine-activity')).toHaveText('Running');
    // Paused from its page (no confirmation), to hold its progress still.
    await page.getByTestId('cmd-xtool.pause').tap();
    await expect(page.getByTestId('machine-activity')).toHaveText('Paused');
    await sameFactsEverywhere(page, id, /^tmp\.gcode$/);
  });

  test('Duet: one percentage in the header, beside the bar and on the bar, on every view', async ({
    page,
    request,
  }) => {
    const id = 'demo-duet';
    await resetSimulators(request, [id]);
    await noJob(page, id);
    await simulator(request, id, 'world', 'demo');
    await page.goto(`/m/${id}`);
    await expect(page.getByTestId('machine-activity')).toHaveText('Running', { timeout: 20_000 });
    await expect(page.getByTestId('duet-job-progress')).toHaveText(/[1-9]\d*\s?%/, { timeout: 60_000 });
    await page.getByTestId('cmd-duet.pause').tap();
    await expect(page.getByTestId('duet-status')).toHaveText('Paused', { timeout: 20_000 });
    await sameFactsEverywhere(page, id, /\S/);

    // The Duet's own job panel: the big figure, its bar and the header say one percentage.
    const shown = percents((await page.getByTestId('duet-job-progress').textContent()) ?? '')[0];
    expect(shown).toBe(percents((await page.getByTestId('job-facts-percent').textContent()) ?? '')[0]);
    const bar = page.getByRole('progressbar', { name: 'Job progress' }).first();
    expect(await barValue(bar)).toBe(shown);
    for (const p of percents((await page.getByTestId('machine-label').textContent()) ?? ''))
      expect(p).toBe(shown);
  });
});
