import { mkdirSync, mkdtempSync, rmSync, writeFileSync } from 'node:fs';
import http from 'node:http';
import type { AddressInfo } from 'node:net';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import { expect, test, type Browser, type Page } from '@playwright/test';
import { Children, freePort, signIn as signInAs, waitFor, writeUsersFile } from './own-server';

/**
 * The alarm centre end to end, on a console of its own (the production server with a users file,
 * the demo machines simulated in it, and an alarm webhook pointed at a receiver this spec runs):
 * a flame raised while no page is open is sent to the webhook and is in the alarm centre when a
 * page opens; it blocks the Duet page until an operator acknowledges it, which is recorded (the
 * list, the audit log, the webhook); a critical alarm of another family is a banner on every page.
 */

const USERS = {
  vera: { role: 'viewer', password: 'viewer-password-1' },
  olga: { role: 'operator', password: 'operator-password-1' },
  sam: { role: 'supervisor', password: 'supervisor-password-1' },
} as const;

let dir = '';
let base = '';
const children = new Children();
const hooked: Array<{ event: string; alarm: { machine: string; key: string; ackBy: string | null } }> = [];
let receiver: http.Server | null = null;

test.describe.configure({ mode: 'serial' });

test.describe('alarm centre', () => {
  test.beforeAll(async ({}, info) => {
    if (info.project.name !== 'desktop') return;
    dir = mkdtempSync(join(tmpdir(), 'shopdeck-alarms-'));
    receiver = http.createServer((req, res) => {
      let text = '';
      req.on('data', (c: Buffer) => (text += c.toString()));
      req.on('end', () => {
        hooked.push(JSON.parse(text) as (typeof hooked)[number]);
        res.writeHead(204);
        res.end();
      });
    });
    await new Promise<void>((r) => receiver?.listen(0, '127.0.0.1', () => r()));
    const hookUrl = `http://127.0.0.1:${(receiver.address() as AddressInfo).port}/hooks/floor-token`;
    writeUsersFile(join(dir, 'users.json'), USERS);
    // The receiver is on this computer: the server's settings file must allow it (the webhook
    // refuses this computer, link-local addresses and the machines otherwise).
    mkdirSync(join(dir, 'data'), { recursive: true });
    writeFileSync(join(dir, 'data', 'settings.json'), JSON.stringify({ webhookAllowHosts: ['127.0.0.1'] }));
    const port = await freePort();
    base = `http://127.0.0.1:${port}`;
    children.start(['--import', 'tsx', 'server/main.ts', '--port', String(port), '--host', '127.0.0.1'], {
      SHOPDECK_MACHINES: 'tests/e2e/demo-machines.json',
      SHOPDECK_USERS: join(dir, 'users.json'),
      SHOPDECK_DATA: join(dir, 'data'),
      SHOPDECK_ALARM_WEBHOOK: hookUrl,
    });
    await waitFor(`${base}/api/session`, 'the console');
  });

  test.afterAll(async () => {
    children.stopAll();
    await new Promise<void>((r) => (receiver ? receiver.close(() => r()) : r()));
    if (dir) rmSync(dir, { recursive: true, force: true });
  });

  test.beforeEach(({}, info) => {
    test.skip(info.project.name !== 'desktop', 'one run is enough: it starts its own console');
  });

  /** A session cookie for the gateway's API (as the console's page sends it). */
  async function apiLogin(name: keyof typeof USERS): Promise<string> {
    const r = await fetch(`${base}/api/login`, {
      method: 'POST',
      headers: { 'Content-Type': 'application/json', 'X-Shopdeck': '1' },
      body: JSON.stringify({ name, password: USERS[name].password }),
    });
    expect(r.status).toBe(200);
    return (r.headers.getSetCookie()[0] ?? '').split(';')[0] ?? '';
  }

  /** A simulator's control, as a supervisor at the machine would trip it (no page open). */
  async function trip(machine: string, id: string): Promise<void> {
    const r = await fetch(`${base}/api/sim/${machine}`, {
      method: 'POST',
      headers: { 'Content-Type': 'application/json', 'X-Shopdeck': '1', cookie: await apiLogin('sam') },
      body: JSON.stringify({ group: 'world', id }),
    });
    expect(r.status).toBe(200);
  }

  const signIn = (browser: Browser, name: keyof typeof USERS, path: string): Promise<Page> =>
    signInAs(browser, base, name, USERS[name], path);

  test('a flame with no page open reaches the webhook and the alarm centre; an operator acknowledges it on the Duet page', async ({
    browser,
  }) => {
    // No browser is open: the console's own watch of the laser sees the flame.
    await trip('demo-xtool', 'flame');
    await expect
      .poll(
        () => hooked.find((h) => h.event === 'alarm.raised' && h.alarm.key === 'xtool-flame')?.alarm.machine,
        {
          timeout: 20_000,
        },
      )
      .toBe('demo-xtool');

    // A viewer sees it on every page, blocking, and cannot acknowledge it.
    const vera = await signIn(browser, 'vera', '/m/demo-duet');
    const veraAlarm = vera.getByTestId('blocking-alarm');
    await expect(veraAlarm).toContainText('FLAME DETECTED');
    await expect(veraAlarm.getByTestId('ack-demo-xtool')).toHaveCount(0);
    await expect(veraAlarm).toContainText('An operator must acknowledge');

    // The operator, on the Duet page.
    const olga = await signIn(browser, 'olga', '/m/demo-duet');
    const alarm = olga.getByTestId('blocking-alarm');
    await expect(alarm).toContainText('Laser bay');
    await expect(alarm).toContainText('FLAME DETECTED');
    await expect(olga.getByTestId('app-page')).toHaveAttribute('inert', '');
    await alarm.getByTestId('ack-demo-xtool').click();
    await expect(alarm).toHaveCount(0);
    await expect(olga.getByTestId('app-page')).not.toHaveAttribute('inert', '');
    // The viewer's page lets go too, without a reload.
    await expect(veraAlarm).toHaveCount(0);

    // Recorded: the alarm centre (who), the audit log, the webhook.
    await olga.getByTestId('nav-alarms').click();
    const table = olga.getByTestId('alarm-table');
    const row = table.getByRole('row').filter({ hasText: 'FLAME DETECTED' }).first();
    await expect(row).toContainText('critical');
    await expect(row).toContainText('Laser bay');
    await expect(row).toContainText('olga');
    const audit = await fetch(`${base}/api/audit?type=alarm-ack`, {
      headers: { cookie: await apiLogin('sam'), 'X-Shopdeck': '1' },
    });
    const entries = (
      (await audit.json()) as { entries: Array<{ type: string; user: string; machine?: string }> }
    ).entries;
    expect(entries.find((e) => e.type === 'alarm-ack')).toMatchObject({
      user: 'olga',
      machine: 'demo-xtool',
    });
    await expect
      .poll(() => hooked.find((h) => h.event === 'alarm.acknowledged')?.alarm.ackBy, { timeout: 20_000 })
      .toBe('olga');
    await vera.context().close();
    await olga.context().close();
  });

  test('a g2core panic is a banner on every page (not blocking) until acknowledged from the alarm centre; sound mutes per tablet', async ({
    browser,
  }) => {
    const olga = await signIn(browser, 'olga', '/');
    await trip('demo-g2core', 'panic');
    const banner = olga.getByTestId('critical-banner');
    await expect(banner).toContainText('PANIC', { timeout: 20_000 });
    // The page stays usable (the machine page clears the alarm).
    await expect(olga.getByTestId('app-page')).not.toHaveAttribute('inert', '');
    await olga.getByTestId('nav-alarms').click();
    await expect(olga.getByTestId('alarms-page')).toBeVisible();
    await expect(banner).toContainText('PANIC');

    // Mute on this tablet: kept across a reload.
    await olga.getByTestId('alarm-sound-setting').click();
    await expect(olga.getByTestId('alarm-sound-setting')).toContainText('muted');
    await olga.reload();
    await expect(olga.getByTestId('alarm-sound-setting')).toContainText('muted');

    // Filters: only critical g2core alarms.
    await olga.getByTestId('alarm-filter-severity').selectOption('critical');
    await olga.getByTestId('alarm-filter-family').selectOption('g2core');
    const rows = olga.getByTestId('alarm-table').getByRole('row');
    await expect(rows.filter({ hasText: 'PANIC' })).toHaveCount(1);
    await expect(rows.filter({ hasText: 'FLAME' })).toHaveCount(0);
    await rows.filter({ hasText: 'PANIC' }).getByRole('button', { name: 'Acknowledge' }).click();
    await expect(rows.filter({ hasText: 'PANIC' })).toContainText('olga');
    await expect(banner).toHaveCount(0);
    await olga.context().close();
  });
});
