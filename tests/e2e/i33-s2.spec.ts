import { expect, test, type Page } from '@playwright/test';
import { DEMO_MACHINES, resetSimulators, simulator } from './simulators';

/**
 * Issue 33 (3–5): the picture must be true. Alarms of other machines are one line, not a block
 * each; a kiosk acknowledges only its own machine's; a critical alarm overrides the state chip
 * everywhere, and the fleet header's counts are a partition of the fleet.
 * Run: SHOPDECK_E2E_PORT=4192 npx playwright test tests/e2e/i33-s2.spec.ts --project=tablet
 */

/** Three critical alarms that do not block: a g2core panic, a torch collision, a heater fault. */
async function threeCritical(page: Page, request: Parameters<typeof simulator>[0]): Promise<void> {
  await simulator(request, 'demo-g2core', 'world', 'panic');
  await simulator(request, 'demo-touchcut', 'world', 'fault');
  await simulator(request, 'demo-duet', 'world', 'heater-fault');
  void page;
}

/** Every demo machine online on the fleet page (an alarm is not replayed to a later socket). */
async function fleetOnline(page: Page): Promise<void> {
  await page.goto('/');
  for (const id of DEMO_MACHINES)
    await expect(page.getByTestId(`tile-${id}`).getByTestId('tile-link')).toHaveText('Online', {
      timeout: 20_000,
    });
}

/** Nothing may move focus onto a stop control. */
async function focusOnStop(page: Page): Promise<boolean> {
  return page.evaluate(() => {
    const el = document.activeElement;
    return !!el && el !== document.body && /stop/i.test(el.textContent ?? '');
  });
}

test.describe('issue 33: alarms and state', () => {
  test.beforeEach(async ({ request }) => {
    await resetSimulators(request);
  });

  test('3: a kiosk shows its own machine’s alarms in full and one line for the rest, without acknowledge', async ({
    page,
    request,
  }) => {
    test.setTimeout(90_000);
    await page.goto('/m/demo-xtool?kiosk');
    await expect(page.getByTestId('kiosk-link')).toHaveText('Online', { timeout: 20_000 });
    await threeCritical(page, request);
    const banner = page.getByTestId('critical-banner');
    await expect(banner.getByTestId('critical-summary')).toHaveText(/3 other alarms in the shop/, {
      timeout: 20_000,
    });
    // Nothing of another machine to acknowledge, no modal, no link away.
    await expect(page.getByRole('button', { name: /acknowledge/i })).toHaveCount(0);
    await expect(page.getByTestId('blocking-alarm')).toHaveCount(0);
    await expect(banner.locator('a[href]')).toHaveCount(0);
    // The banner is one line (a kiosk's buttons are glove-sized); the kiosk's stop stays on the screen.
    const box = await banner.boundingBox();
    expect(box?.height ?? 999).toBeLessThanOrEqual(80);
    const stop = page.locator('[data-kiosk="stop"]');
    if ((await stop.count()) > 0) {
      const s = await stop.boundingBox();
      expect((s?.y ?? 9999) + (s?.height ?? 0)).toBeLessThanOrEqual(768);
    }
    await page.screenshot({ path: '/tmp/s2-kiosk-others.png' });

    // A flame on the laser itself: its own alarm, in full, with its acknowledgement.
    await expect(async () => {
      await simulator(request, 'demo-xtool', 'world', 'flame');
      await expect(page.getByTestId('blocking-alarm')).toBeVisible({ timeout: 3000 });
    }).toPass({ timeout: 20_000 });
    const own = page.getByTestId('blocking-alarm');
    await expect(own).toContainText('FLAME DETECTED');
    await expect(own.getByTestId('ack-demo-xtool')).toBeVisible();
    await expect(own.getByTestId('ack-demo-g2core')).toHaveCount(0);
    expect(await focusOnStop(page)).toBe(false);
  });

  test('3: a kiosk at another machine is not blocked by the laser’s flame: one line, no acknowledge', async ({
    page,
    request,
  }) => {
    test.setTimeout(90_000);
    await page.goto('/m/demo-g2core?kiosk');
    await expect(page.getByTestId('kiosk-link')).toHaveText('Online', { timeout: 20_000 });
    await simulator(request, 'demo-xtool', 'world', 'flame');
    await expect(page.getByTestId('critical-summary')).toHaveText(/1 other alarm in the shop/, {
      timeout: 20_000,
    });
    await expect(page.getByTestId('blocking-alarm')).toHaveCount(0);
    await expect(page.getByTestId('app-page')).not.toHaveAttribute('inert', '');
    await expect(page.getByTestId('ack-demo-xtool')).toHaveCount(0);
  });

  test('4: three critical alarms are one compact line; acknowledge on the machine’s page', async ({
    page,
    request,
  }) => {
    test.setTimeout(90_000);
    await fleetOnline(page);
    const firstTile = page.getByTestId(`tile-${DEMO_MACHINES[0]}`);
    const before = (await firstTile.boundingBox())?.y ?? 0;
    await threeCritical(page, request);
    const banner = page.getByTestId('critical-banner');
    const line = banner.getByTestId('critical-summary');
    await expect(line).toHaveText(/3 critical — /, { timeout: 20_000 });
    for (const name of ['CNC router — g2core', 'Plasma table — TouchCut', 'Printer bay — Duet 3'])
      await expect(line).toContainText(name);
    await expect(banner.getByRole('link', { name: 'View' })).toHaveAttribute('href', '/alarms');
    await expect(banner.getByRole('button', { name: /acknowledge/i })).toHaveCount(0);
    const box = await banner.boundingBox();
    expect(box?.height ?? 999).toBeLessThanOrEqual(64);
    // The tiles move down by one line at most (they started near the bottom of 768 before).
    const after = (await firstTile.boundingBox())?.y ?? 9999;
    expect(after - before).toBeLessThanOrEqual(64);
    expect(after).toBeLessThan(400);
    expect(await focusOnStop(page)).toBe(false);
    await page.screenshot({ path: '/tmp/s2-fleet-three.png' });

    // The machine's page: its own alarm in full with the acknowledgement, the others one line.
    await page.goto('/m/demo-g2core');
    await expect(page.getByTestId('critical-demo-g2core')).toContainText('PANIC', { timeout: 20_000 });
    await expect(page.getByTestId('critical-summary')).toHaveText(/2 critical — /);
    expect(await focusOnStop(page)).toBe(false);
    await page.screenshot({ path: '/tmp/s2-machine-three.png' });
    await page.getByTestId('ack-demo-g2core').click();
    await expect(page.getByTestId('critical-demo-g2core')).toHaveCount(0, { timeout: 20_000 });
    await expect(page.getByTestId('critical-summary')).toHaveText(/2 critical — /);
  });

  test('5: a critical alarm overrides the state chip everywhere; the header counts are a partition', async ({
    page,
    request,
  }) => {
    test.setTimeout(120_000);
    await fleetOnline(page);
    await simulator(request, 'demo-duet', 'world', 'demo');
    const duet = page.getByTestId('tile-demo-duet');
    await expect(duet.getByTestId('tile-activity')).toHaveText('Running', { timeout: 30_000 });
    await simulator(request, 'demo-duet', 'world', 'heater-fault');
    await expect(duet.getByTestId('tile-alarm')).toContainText(/heater/i, { timeout: 20_000 });
    await expect(duet.getByTestId('tile-activity')).toHaveText(/^Alarm · was /);
    await expect(duet.getByTestId('tile-activity')).not.toHaveText(/^Running/);

    // The counts add up to the fleet, whatever the states.
    const total = async () => {
      let n = 0;
      for (const b of await page.getByTestId('fleet-summary').locator('[data-testid^="summary-"]').all())
        n += Number(/^\d+/.exec((await b.textContent()) ?? '')?.[0] ?? 'NaN');
      return n;
    };
    await expect(page.getByTestId('summary-alarm')).toHaveText(/^[1-9]\d* in alarm/);
    expect(await total()).toBe(DEMO_MACHINES.length);

    // A flame on the laser: its chip is no longer "Idle".
    await simulator(request, 'demo-xtool', 'world', 'flame');
    await expect(page.getByTestId('blocking-alarm')).toContainText('FLAME DETECTED', { timeout: 20_000 });
    await expect(page.getByTestId('tile-demo-xtool').getByTestId('tile-activity')).toHaveText(/^Alarm/);
    expect(await total()).toBe(DEMO_MACHINES.length);
    await expect(page.getByTestId('summary-alarm')).toHaveText('2 in alarm');
    await page.getByTestId('ack-demo-xtool').click();
    await expect(page.getByTestId('blocking-alarm')).toHaveCount(0, { timeout: 20_000 });

    // The machine page's header, and the kiosk.
    await page.goto('/m/demo-duet');
    await expect(page.getByTestId('machine-activity')).toHaveText(/^Alarm · was /, { timeout: 20_000 });
    await page.goto('/m/demo-duet?kiosk');
    await expect(page.getByTestId('kiosk-activity')).toHaveText(/^Alarm · was /, { timeout: 20_000 });

    // The wall's card, at 1920×1080.
    await page.setViewportSize({ width: 1920, height: 1080 });
    await page.goto('/wall');
    await expect(page.getByTestId('wall-card-demo-duet').getByTestId('wall-activity')).toHaveText(
      /^Alarm · was /,
      { timeout: 20_000 },
    );
    await page.screenshot({ path: '/tmp/s2-wall.png' });
  });
});
