import { expect, test, type Page } from '@playwright/test';
import { resetSimulators, simulator } from './simulators';

/**
 * Issue 33, the leftovers of items 10 and 13, on a 1024×768 touch tablet (the `tablet` project):
 * - 10: the Duet message box's emergency stop and g2core's jog STOP ask the same question as the
 *   job control row's emergency stop (one tap sent them before), and say what they did; the
 *   question is a switch per console in the top bar's menu, on by default on a touch screen.
 * - 13: g2core's overrides in words ("Feed override: off in the machine's settings"), opening
 *   Prunt's config writes no audit entry, and no developer or protocol words on any family's pages.
 */

test.beforeEach(({}, info) => {
  test.skip(info.project.name !== 'tablet', 'the tablet (1024×768, touch)');
});

function section(page: Page, name: string) {
  return page.getByRole('navigation', { name: 'Machine sections' }).getByRole('link', { name, exact: true });
}

async function running(page: Page, request: Parameters<typeof resetSimulators>[0], id: string, path = '') {
  await simulator(request, id, 'world', 'demo');
  await page.goto(`/m/${id}${path}`);
  await expect(page.getByTestId('machine-link')).toHaveText('Online');
  await expect(page.getByTestId('machine-activity')).toHaveText('Running', { timeout: 30_000 });
}

const stopFocused = (page: Page) =>
  page.evaluate(() => document.activeElement?.closest('[data-stop]') !== null);

test.describe('issue 33 (10): every emergency stop asks first on touch', () => {
  test.beforeEach(async ({ request }) => {
    await resetSimulators(request, ['demo-duet', 'demo-g2core']);
  });

  test("the Duet message box's emergency stop asks, keeps running on the dismiss, then says what it did", async ({
    page,
    request,
  }) => {
    await running(page, request, 'demo-duet');
    await simulator(request, 'demo-duet', 'world', 'box-4');
    const box = page.getByTestId('duet-messagebox');
    await expect(box).toContainText('Which filament is loaded?');
    const estop = box.getByTestId('duet-messagebox-estop');
    await expect(stopFocused(page)).resolves.toBe(false);
    await estop.tap();
    const question = page.getByTestId('confirm-dialog');
    await expect(question).toContainText('Emergency stop: halt the machine now?');
    await expect(question.getByTestId('confirm-keep')).toHaveText('Keep running');
    await expect(question.getByTestId('confirm-keep')).toBeFocused();
    await page.screenshot({ path: '/tmp/w13-duet-box-estop-question.png' });
    // Asked, not sent: the print goes on and the box is still there.
    await question.getByTestId('confirm-keep').tap();
    await expect(question).toHaveCount(0);
    await page.waitForTimeout(1500);
    await expect(page.getByTestId('machine-activity')).toHaveText('Running');
    await expect(box).toBeVisible();
    expect(await stopFocused(page)).toBe(false);
    // Now meant: sent once, and said on the page.
    await estop.tap();
    const sent = page.waitForRequest((r) => r.method() === 'POST' && /M112/.test(r.postData() ?? ''));
    await question.getByTestId('confirm-yes').tap();
    await sent;
    await expect(page.getByTestId('duet-estop-said')).toContainText('Emergency stop sent');
    await expect(page.getByTestId('duet-estop-said')).toContainText('the job has ended');
    await expect(page.getByTestId('machine-activity')).not.toHaveText('Running', { timeout: 15_000 });
    expect(await stopFocused(page)).toBe(false);
    await page.screenshot({ path: '/tmp/w13-duet-box-estop-said.png' });
  });

  test("g2core's jog STOP asks, keeps moving on the dismiss, then says what it did", async ({
    page,
    request,
  }) => {
    await running(page, request, 'demo-g2core');
    await section(page, 'Jog & home').tap();
    const stop = page.getByTestId('g2-bigstop');
    await expect(stop).not.toHaveAttribute('aria-disabled', 'true');
    await stop.tap();
    const question = page.getByTestId('confirm-dialog');
    await expect(question).toContainText('STOP: halt what moves now?');
    await expect(question.getByTestId('confirm-keep')).toHaveText('Keep moving');
    await question.getByTestId('confirm-keep').tap();
    await expect(question).toHaveCount(0);
    await page.waitForTimeout(1500);
    await expect(page.getByTestId('machine-activity')).toHaveText('Running');
    expect(await stopFocused(page)).toBe(false);
    await stop.tap();
    await question.getByTestId('confirm-yes').tap();
    await expect(page.getByTestId('g2-stop-said')).toContainText('STOP sent');
    await expect(page.getByTestId('machine-activity')).not.toHaveText('Running', { timeout: 15_000 });
    expect(await stopFocused(page)).toBe(false);
    await page.screenshot({ path: '/tmp/w13-g2-stop-said.png' });
  });

  test('the question is a switch per console in the menu: on by default on touch, off sends at the first tap', async ({
    page,
    request,
  }) => {
    await page.goto('/');
    await page.getByTestId('topbar-menu-button').tap();
    const toggle = page.getByRole('switch', { name: /Ask before an emergency stop on this screen/ });
    await expect(toggle).toBeVisible();
    await expect(toggle).toBeChecked();
    await expect(page.getByTestId('estop-confirm-setting')).toContainText('on by default on touch screens');
    const box = await page.getByTestId('estop-confirm-setting').boundingBox();
    expect(box?.height ?? 0).toBeGreaterThanOrEqual(44);
    await page.screenshot({ path: '/tmp/w13-menu-switch-on.png' });
    await page.getByTestId('estop-confirm-setting').tap();
    await expect(toggle).not.toBeChecked();
    expect(await page.evaluate(() => localStorage.getItem('shopdeck.estop-confirm'))).toBe('off');
    await expect(page.getByTestId('estop-confirm-setting')).toContainText('sent at the first tap');
    await page.screenshot({ path: '/tmp/w13-menu-switch-off.png' });

    // Kept on this console: off, g2core's STOP is sent by one tap.
    await running(page, request, 'demo-g2core', '/jog');
    await page.getByTestId('g2-bigstop').tap();
    await expect(page.getByTestId('confirm-dialog')).toHaveCount(0);
    await expect(page.getByTestId('g2-stop-said')).toContainText('STOP sent');

    // Back on: the job row's emergency stop asks again.
    await page.getByTestId('topbar-menu-button').tap();
    await page.getByTestId('estop-confirm-setting').tap();
    await expect(toggle).toBeChecked();
    expect(await page.evaluate(() => localStorage.getItem('shopdeck.estop-confirm'))).toBe('on');
    await page.keyboard.press('Escape');
    await running(page, request, 'demo-duet');
    await page.getByTestId('job-controls').getByRole('button', { name: 'Emergency stop', exact: true }).tap();
    await expect(page.getByTestId('confirm-dialog')).toContainText('Emergency stop: halt the machine now?');
    await page.getByTestId('confirm-keep').tap();
    await expect(page.getByTestId('machine-activity')).toHaveText('Running');
  });
});

/** Developer and protocol words no page may show (outside a console's own transcript). */
const PATTERNS: Array<[string, RegExp]> = [
  ['a raw firmware status string', /\bok:[A-Z_]{3,}/],
  ['a g2core override token', /\b(mfoe|mtoe|ssoe) ?= ?\d/],
  ['a raw exponent number', /(?<![\w.])-?\d+(\.\d+)?[eE][+-]?\d+\b/],
  ['undefined / null / NaN', /\b(undefined|null|NaN)\b/],
  ['a camelCase key', /\b[a-z]+[A-Z][a-z]+[A-Za-z]*\b/],
  ['a doubled word', /\b([A-Za-z]{3,}) \1\b/i],
  ['[object Object]', /\[object \w+\]/],
];
/** Brand names spelled in camel case by their makers. */
const ALLOWED = new Set([
  'xTool',
  'RepRapFirmware',
  'PrusaSlicer',
  'SuperSlicer',
  'OrcaSlicer',
  'iPad',
  'macOS',
]);

/** What the page says (its text and its fields), without a console's transcript of the wire. */
async function pageWords(page: Page): Promise<string> {
  return page.evaluate(() => {
    const root = document.body.cloneNode(true) as HTMLElement;
    for (const el of root.querySelectorAll('pre, code, textarea, [data-transcript], script, style, noscript'))
      el.remove();
    document.body.append(root);
    root.style.position = 'absolute';
    const text = root.innerText;
    root.remove();
    const values = [
      ...document.querySelectorAll<HTMLInputElement>('input[type="text"], input:not([type])'),
    ].map((i) => i.value);
    return `${text}\n${values.join('\n')}`;
  });
}

function findings(text: string): string[] {
  const found: string[] = [];
  for (const line of text.split('\n'))
    for (const [what, re] of PATTERNS) {
      const m = re.exec(line);
      if (m && !(what === 'a camelCase key' && ALLOWED.has(m[0])))
        found.push(`${what}: "${line.trim().slice(0, 120)}"`);
    }
  return found;
}

test.describe('issue 33 (13): no developer or protocol words on any family page', () => {
  test.beforeEach(async ({ request }) => {
    await resetSimulators(request);
  });

  test('g2core overrides in words: "Feed override: off", the firmware token only as a subtitle', async ({
    page,
  }) => {
    await page.goto('/m/demo-g2core');
    await expect(page.getByTestId('machine-link')).toHaveText('Online');
    const off = page.getByTestId('g2-override-mfo-off');
    await expect(off).toContainText('Feed override: off — the machine runs at 100 %');
    await expect(off).toContainText('Feed override enable');
    await expect(page.getByTestId('g2-override-mfo')).not.toContainText('mfoe = 0');
    await page.getByTestId('g2-override-mfo').screenshot({ path: '/tmp/w13-g2-override.png' });
  });

  test('opening Prunt’s config writes no audit entry', async ({ page }) => {
    const count = async () => {
      const r = await page.request.get('/api/audit?machine=demo-prunt&type=command&limit=500');
      expect(r.ok()).toBe(true);
      const body = (await r.json()) as { entries?: Array<{ path?: string }>; total?: number };
      return (body.entries ?? []).filter((e) => (e.path ?? '').startsWith('/config')).length;
    };
    const before = await count();
    await page.goto('/m/demo-prunt');
    await expect(page.getByTestId('machine-link')).toHaveText('Online');
    const steppers = page
      .getByRole('button', { name: 'Steppers', exact: true })
      .or(page.getByRole('tab', { name: 'Steppers', exact: true }))
      .first();
    // The editor open (schema and values read), twice.
    await section(page, 'Config').tap();
    await expect(steppers).toBeVisible();
    await page.reload();
    await expect(page.getByTestId('machine-link')).toHaveText('Online');
    await expect(steppers).toBeVisible();
    await page.waitForTimeout(1000);
    expect(await count()).toBe(before);
    await page.goto('/audit');
    await expect(page.getByTestId('audit-table')).toBeVisible();
    await expect(page.getByTestId('audit-table')).not.toContainText('config values');
  });

  test('every section of every family, running and idle, and the fleet', async ({ page, request }) => {
    test.setTimeout(240_000);
    const found: string[] = [];
    await page.goto('/');
    await expect(page.getByText(/\d+ machines/).first()).toBeVisible();
    await page.waitForTimeout(2000);
    found.push(...findings(await pageWords(page)).map((f) => `fleet: ${f}`));
    for (const id of ['demo-g2core', 'demo-xtool', 'demo-duet', 'demo-prunt', 'demo-touchcut']) {
      for (const phase of ['idle', 'running'] as const) {
        if (phase === 'running') await simulator(request, id, 'world', 'demo').catch(() => undefined);
        await page.goto(`/m/${id}`);
        await expect(page.getByTestId('machine-link')).toHaveText('Online');
        const links = page.getByRole('navigation', { name: 'Machine sections' }).getByRole('link');
        const names = (await links.allInnerTexts())
          .map((n) => n.trim())
          .filter((n) => n !== 'Console' && n !== 'Simulator');
        for (const name of names) {
          await section(page, name).tap();
          await page.waitForTimeout(1200);
          found.push(...findings(await pageWords(page)).map((f) => `${id} ${phase} ${name}: ${f}`));
        }
      }
    }
    expect([...new Set(found)]).toEqual([]);
  });
});
