import { mkdtempSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import { expect, test, type Page } from '@playwright/test';
import { Children, freePort, signIn, waitFor, writeUsersFile } from './own-server';

/**
 * Issue 33 (sessions): a restart of the server keeps every screen signed in (the wall and a kiosk
 * go on, and an alarm raised after the restart reaches the wall); a session really gone says
 * "Signed out — sign in again" with the sign-in, never "Offline" or "No alarms". The spec runs its
 * own console (own-server.ts) so that it can restart it.
 */

const USERS = {
  vera: { role: 'viewer', password: 'viewer-password-1' },
  olga: { role: 'operator', password: 'operator-password-1' },
  sam: { role: 'supervisor', password: 'supervisor-password-1' },
} as const;

let dir = '';
let port = 0;
let base = '';
const children = new Children();

test.describe.configure({ mode: 'serial' });

async function start(data: string): Promise<void> {
  children.start(['--import', 'tsx', 'server/main.ts', '--port', String(port), '--host', '127.0.0.1'], {
    SHOPDECK_MACHINES: 'tests/e2e/demo-machines.json',
    SHOPDECK_USERS: join(dir, 'users.json'),
    SHOPDECK_DATA: data,
  });
  await waitFor(`${base}/api/session`, 'the console');
}

async function stop(): Promise<void> {
  children.stopAll();
  // Gone before the next one takes the port.
  for (let i = 0; i < 80; i++) {
    try {
      await fetch(`${base}/api/session`);
    } catch {
      return;
    }
    await new Promise((r) => setTimeout(r, 250));
  }
  throw new Error('the console did not stop');
}

async function trip(machine: string, id: string): Promise<void> {
  const login = await fetch(`${base}/api/login`, {
    method: 'POST',
    headers: { 'Content-Type': 'application/json', 'X-Shopdeck': '1' },
    body: JSON.stringify({ name: 'sam', password: USERS.sam.password }),
  });
  const cookie = (login.headers.getSetCookie()[0] ?? '').split(';')[0] ?? '';
  const r = await fetch(`${base}/api/sim/${machine}`, {
    method: 'POST',
    headers: { 'Content-Type': 'application/json', 'X-Shopdeck': '1', cookie },
    body: JSON.stringify({ group: 'world', id }),
  });
  expect(r.status).toBe(200);
}

/** What a screen must never show while it cannot know. */
async function noFalsePicture(page: Page): Promise<void> {
  await expect(page.getByText('No alarms', { exact: true })).toHaveCount(0);
  await expect(page.getByText(/^Offline/)).toHaveCount(0);
}

test.describe('sessions across a restart of the server (issue 33)', () => {
  test.beforeAll(async ({}, info) => {
    if (info.project.name !== 'tablet') return;
    dir = mkdtempSync(join(tmpdir(), 'shopdeck-i33-s1-'));
    writeUsersFile(join(dir, 'users.json'), USERS);
    port = await freePort();
    base = `http://127.0.0.1:${port}`;
    await start(join(dir, 'data'));
  });

  test.afterAll(() => {
    children.stopAll();
    if (dir) rmSync(dir, { recursive: true, force: true });
  });

  test.beforeEach(({}, info) => {
    test.skip(info.project.name !== 'tablet', 'one run: it restarts its own console');
  });

  test('the wall (1920×1080) and a kiosk (1024×768) go on after a restart; a session gone says "Signed out — sign in again"', async ({
    browser,
  }) => {
    test.setTimeout(180_000);
    const wall = await signIn(browser, base, 'vera', USERS.vera, '/');
    await wall.setViewportSize({ width: 1920, height: 1080 });
    await wall.goto('/wall');
    await expect(wall.getByTestId('wall-alarm-count')).toHaveText('No alarms', { timeout: 20_000 });
    const kiosk = await signIn(browser, base, 'olga', USERS.olga, '/');
    await kiosk.goto('/m/demo-g2core?kiosk');
    await expect(kiosk.getByTestId('kiosk-demo-g2core')).toBeVisible({ timeout: 20_000 });
    await wall.screenshot({ path: '/tmp/s1-wall-before.png' });

    await stop();
    await start(join(dir, 'data'));

    // Signed in still: an alarm raised after the restart reaches the wall.
    await trip('demo-xtool', 'flame');
    await expect(wall.getByTestId('wall-alarm-count')).toContainText('1 in alarm', { timeout: 30_000 });
    await expect(wall.getByTestId('wall-spotlight')).toContainText('Laser bay', { timeout: 20_000 });
    await expect(wall.getByText('Signed out — sign in again')).toHaveCount(0);
    await expect(kiosk.getByTestId('login-form')).toHaveCount(0);
    await expect(kiosk.getByTestId('kiosk-demo-g2core')).toBeVisible();
    await wall.screenshot({ path: '/tmp/s1-wall-after-restart.png' });

    // A server on a fresh data folder: these sessions are really gone.
    await stop();
    await start(join(dir, 'fresh'));
    await expect(wall.getByText(/Signed out — sign in again/)).toBeVisible({ timeout: 30_000 });
    await expect(wall.getByTestId('wall-sign-in')).toBeVisible();
    await noFalsePicture(wall);
    await expect(kiosk.getByTestId('login-form')).toBeVisible({ timeout: 30_000 });
    await expect(kiosk.getByText('Signed out — sign in again')).toBeVisible();
    await noFalsePicture(kiosk);
    await wall.screenshot({ path: '/tmp/s1-wall-signed-out.png' });
    await kiosk.screenshot({ path: '/tmp/s1-kiosk-signed-out.png' });
  });
});
