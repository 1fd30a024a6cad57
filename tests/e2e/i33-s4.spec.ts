import { expect, test, type Locator, type Page } from '@playwright/test';
import { resetSimulators, simulator } from './simulators';

/**
 * Issue 33, items 9 to 12, on a 1024×768 touch tablet, in every family that takes commands: one
 * job control row (the kiosk's) with one vocabulary, pause and stop apart in the same order, the
 * enabled action filled and an unavailable one faint with its reason as text, an emergency stop
 * that asks first on touch and says what it did, a dismiss that says what it keeps, the state a
 * pill. Against the demo fleet's simulators (tests/e2e/simulators.ts).
 */

interface Family {
  id: string;
  pause: string;
  resume: string;
  stop: string;
  keep: string;
}

const FAMILIES: Family[] = [
  {
    id: 'demo-g2core',
    pause: 'g2core.feedhold',
    resume: 'g2core.resume',
    stop: 'g2core.kill',
    keep: 'Keep cutting',
  },
  {
    id: 'demo-xtool',
    pause: 'xtool.pause',
    resume: 'xtool.resume',
    stop: 'xtool.stop',
    keep: 'Keep cutting',
  },
  { id: 'demo-duet', pause: 'duet.pause', resume: 'duet.resume', stop: 'duet.cancel', keep: 'Keep printing' },
  {
    id: 'demo-prunt',
    pause: 'prunt.pause',
    resume: 'prunt.resume',
    stop: 'prunt.cancel',
    keep: 'Keep printing',
  },
];

async function runningDemo(page: Page, request: Parameters<typeof resetSimulators>[0], id: string) {
  await simulator(request, id, 'world', 'demo');
  await page.goto(`/m/${id}`);
  await expect(page.getByTestId('machine-link')).toHaveText('Online');
  await expect(page.getByTestId('machine-activity')).toHaveText('Running', { timeout: 30_000 });
}

const style = (l: Locator, prop: string) =>
  l.evaluate((el, p) => getComputedStyle(el).getPropertyValue(p), prop);

/** Transparent (no fill): `rgba(0, 0, 0, 0)` or `transparent`. */
const unfilled = (bg: string) => bg === 'transparent' || /rgba\(\d+, \d+, \d+, 0\)/.test(bg);

test.describe('issue 33: one job control row', () => {
  test.beforeEach(async ({ request }, info) => {
    test.skip(info.project.name !== 'tablet', 'the tablet (1024×768, touch)');
    await resetSimulators(
      request,
      FAMILIES.map((f) => f.id),
    );
  });

  for (const f of FAMILIES) {
    test(`${f.id}: item 9, the enabled action is filled, an unavailable one faint with its reason as text`, async ({
      page,
      request,
    }) => {
      await runningDemo(page, request, f.id);
      const pause = page.getByTestId(`cmd-${f.pause}`);
      const resume = page.getByTestId(`cmd-${f.resume}`);
      await expect(pause).not.toHaveAttribute('aria-disabled', 'true');
      await expect(resume).toHaveAttribute('aria-disabled', 'true');
      // Filled (a background) versus faint (none, a dashed border, muted text).
      expect(unfilled(await style(pause, 'background-color'))).toBe(false);
      expect(unfilled(await style(resume, 'background-color'))).toBe(true);
      expect(await style(resume, 'border-top-style')).toBe('dashed');
      expect(await style(resume, 'color')).not.toBe(await style(pause, 'color'));
      // The reason is text under it, visible without hovering.
      const reason = page.getByTestId(`cmd-reason-${f.resume}`);
      await expect(reason).toBeVisible();
      await expect(reason).not.toHaveText('');
      const r = await resume.boundingBox();
      const t = await reason.boundingBox();
      if (!r || !t) throw new Error('no box');
      expect(t.y).toBeGreaterThanOrEqual(r.y + r.height - 1);
      await page.screenshot({ path: `/tmp/s4-after-${f.id}.png` });
    });

    test(`${f.id}: item 10, stop job apart from pause, in the same order, labelled in one vocabulary`, async ({
      page,
      request,
    }) => {
      await runningDemo(page, request, f.id);
      const row = page.getByTestId('job-controls');
      // Item 12: the same words in every family; the firmware's own under them.
      const pause = row.getByRole('button', { name: 'Pause', exact: true });
      const resume = row.getByRole('button', { name: 'Resume', exact: true });
      const stop = row.getByRole('button', { name: 'Stop job', exact: true });
      await expect(pause).toHaveAttribute('data-testid', `cmd-${f.pause}`);
      await expect(resume).toHaveAttribute('data-testid', `cmd-${f.resume}`);
      await expect(stop).toHaveAttribute('data-testid', `cmd-${f.stop}`);
      const p = await pause.boundingBox();
      const r = await resume.boundingBox();
      const s = await stop.boundingBox();
      if (!p || !r || !s) throw new Error('a job control has no box');
      // Order: pause, resume, then stop to the right, 48 px or more from either.
      expect(p.x).toBeLessThan(r.x);
      expect(r.x + r.width).toBeLessThan(s.x);
      expect(s.x - (r.x + r.width)).toBeGreaterThanOrEqual(48);
      expect(s.x - (p.x + p.width)).toBeGreaterThanOrEqual(48);
      // One row of controls on the page (no family's own duplicate).
      await expect(page.getByTestId(`cmd-${f.pause}`)).toHaveCount(1);
      await expect(page.getByTestId(`cmd-${f.stop}`)).toHaveCount(1);
    });

    test(`${f.id}: item 11, the stop question's dismiss says what it keeps, and keeps it`, async ({
      page,
      request,
    }) => {
      await runningDemo(page, request, f.id);
      const stop = page.getByTestId(`cmd-${f.stop}`);
      // Duet cancels a paused print only (as its own web control does): pause first.
      if ((await stop.getAttribute('aria-disabled')) === 'true') {
        await page.getByTestId(`cmd-${f.pause}`).tap();
        await expect(stop).not.toHaveAttribute('aria-disabled', 'true');
      }
      await stop.tap();
      const dialog = page.getByTestId('confirm-dialog');
      await expect(dialog).toBeVisible();
      const keep = dialog.getByTestId('confirm-keep');
      await expect(keep).toHaveText(f.keep);
      await expect(dialog.getByRole('button', { name: 'Cancel', exact: true })).toHaveCount(0);
      // Neutral: not the danger colour of the stop itself.
      expect(await style(keep, 'background-color')).not.toBe(
        await style(dialog.getByTestId('confirm-yes'), 'background-color'),
      );
      await expect(keep).toBeFocused();
      const before = await page.getByTestId('machine-activity').textContent();
      await keep.tap();
      await expect(dialog).toHaveCount(0);
      // Nothing was sent, and focus did not land on the stop control.
      await page.waitForTimeout(1500);
      await expect(page.getByTestId('machine-activity')).toHaveText(before ?? '');
      expect(await page.evaluate(() => document.activeElement?.closest('[data-stop]') !== null)).toBe(false);
    });
  }

  test('item 10: the Duet emergency stop asks first on touch, is sent once, and says what it did', async ({
    page,
    request,
  }) => {
    const id = 'demo-duet';
    await runningDemo(page, request, id);
    const estop = page
      .getByTestId('job-controls')
      .getByRole('button', { name: 'Emergency stop', exact: true });
    await expect(page.getByTestId('job-term-estop')).toHaveText('M112');
    await estop.tap();
    const dialog = page.getByTestId('confirm-dialog');
    await expect(dialog).toContainText('Emergency stop: halt the machine now?');
    // Asked, not sent: the print goes on.
    await page.waitForTimeout(1500);
    await expect(page.getByTestId('machine-activity')).toHaveText('Running');
    await expect(dialog.getByTestId('confirm-keep')).toHaveText('Keep running');
    const audit = page.waitForResponse(
      (r) => r.url().includes('/rr_gcode') || r.url().includes('/machine/code'),
    );
    await dialog.getByTestId('confirm-yes').tap();
    await audit;
    // Said on screen afterwards.
    await expect(page.getByTestId('job-said')).toContainText('Emergency stop sent');
    await expect(page.getByTestId('job-said')).toContainText('the job has ended');
    await expect(page.getByTestId('machine-activity')).not.toHaveText('Running');
    expect(await page.evaluate(() => document.activeElement?.closest('[data-stop]') !== null)).toBe(false);
    await page.screenshot({ path: '/tmp/s4-after-duet-estop.png' });
  });

  test('item 12: first tab Status, console Console, the state a pill in every family', async ({ page }) => {
    for (const id of [...FAMILIES.map((f) => f.id), 'demo-touchcut']) {
      await page.goto(`/m/${id}`);
      await expect(page.getByTestId('machine-link')).toHaveText('Online');
      const nav = page.getByRole('navigation', { name: 'Machine sections' });
      await expect(nav.getByRole('link').first()).toHaveText('Status');
      await expect(nav.getByRole('link', { name: 'G-code', exact: true })).toHaveCount(0);
      await expect(nav.getByRole('link', { name: 'Overview', exact: true })).toHaveCount(0);
      await expect(nav.getByRole('link', { name: 'Machine', exact: true })).toHaveCount(0);
      if (id !== 'demo-touchcut')
        await expect(nav.getByRole('link', { name: 'Console', exact: true })).toHaveCount(1);
    }
    // g2core's own state is the same pill as the page's state, not drawn like a button.
    await page.goto('/m/demo-g2core');
    const stat = page.getByTestId('g2-stat');
    await expect(stat).toBeVisible();
    const badge = page.getByTestId('machine-activity');
    expect(await stat.evaluate((el) => el.tagName)).not.toBe('BUTTON');
    expect(await stat.getAttribute('role')).toBeNull();
    for (const prop of ['border-top-left-radius', 'font-size', 'border-top-style'])
      expect(await style(stat, prop)).toBe(await style(badge, prop));
    await page.screenshot({ path: '/tmp/s4-after-g2core-status.png' });
  });
});
