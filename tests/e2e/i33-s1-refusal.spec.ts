import { mkdtempSync, rmSync, writeFileSync } from 'node:fs';
import http from 'node:http';
import type { AddressInfo } from 'node:net';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import { expect, test } from '@playwright/test';
import { Children, freePort, signIn, waitFor, writeUsersFile } from './own-server';

/**
 * Issue 33 (item 2): a controller that refuses its API key (HTTP 401, as a TouchCut does) is that
 * machine's problem only: the page's read socket stays open and no other machine's tile shows
 * "Reconnecting". The spec runs its own console with a TouchCut at a stub that answers 401 to
 * everything, beside the simulated xTool.
 */

const USERS = { vera: { role: 'viewer', password: 'viewer-password-1' } } as const;

let dir = '';
let base = '';
let refused = 0;
let stub: http.Server | null = null;
const children = new Children();

test.describe('a controller’s refusal (issue 33)', () => {
  test.beforeAll(async ({}, info) => {
    if (info.project.name !== 'tablet') return;
    dir = mkdtempSync(join(tmpdir(), 'shopdeck-i33-s1r-'));
    stub = http.createServer((req, res) => {
      refused++;
      req.resume();
      res.writeHead(401, { 'Content-Type': 'application/json' });
      res.end(JSON.stringify({ error: 'invalid api key' }));
    });
    await new Promise<void>((r) => stub?.listen(0, '127.0.0.1', () => r()));
    const stubPort = (stub.address() as AddressInfo).port;
    writeFileSync(
      join(dir, 'machines.json'),
      JSON.stringify({
        machines: [
          { id: 'demo-xtool', name: 'Laser bay — xTool D1 Pro', kind: 'xtool', simulated: true },
          {
            id: 'plasma',
            name: 'Plasma table — TouchCut',
            kind: 'touchcut',
            url: `http://127.0.0.1:${stubPort}`,
            apiKey: 'a-key-the-table-refuses-1',
          },
        ],
      }),
    );
    writeUsersFile(join(dir, 'users.json'), USERS);
    const port = await freePort();
    base = `http://127.0.0.1:${port}`;
    children.start(['--import', 'tsx', 'server/main.ts', '--port', String(port), '--host', '127.0.0.1'], {
      SHOPDECK_MACHINES: join(dir, 'machines.json'),
      SHOPDECK_USERS: join(dir, 'users.json'),
      SHOPDECK_DATA: join(dir, 'data'),
    });
    await waitFor(`${base}/api/session`, 'the console');
  });

  test.afterAll(async () => {
    children.stopAll();
    await new Promise<void>((r) => (stub ? stub.close(() => r()) : r()));
    if (dir) rmSync(dir, { recursive: true, force: true });
  });

  test.beforeEach(({}, info) => {
    test.skip(info.project.name !== 'tablet', 'one run is enough: it starts its own console');
  });

  test('the TouchCut’s 401 never makes the xTool’s tile say "Reconnecting"', async ({ browser }) => {
    test.setTimeout(90_000);
    const page = await signIn(browser, base, 'vera', USERS.vera, '/');
    // Off the console first: a read socket the signed-in page opens late (on a loaded machine,
    // after this listener was added) is not this page's, and a reload does not always report its
    // close (seen in CI: opened 2, closed 0).
    await page.goto('about:blank');
    // The page's read socket (/api/reads): opened once, never closed by a controller's answer.
    const readSockets = { opened: 0, closed: 0 };
    page.on('websocket', (ws) => {
      if (!ws.url().endsWith('/api/reads')) return;
      readSockets.opened++;
      ws.on('close', () => readSockets.closed++);
    });
    await page.goto(`${base}/`);
    const xtool = page.getByTestId('tile-demo-xtool');
    await expect(xtool).toContainText('Online', { timeout: 20_000 });
    // From now on, every state the xTool's tile passes through, however short (a blink of a second counts).
    await page.evaluate(() => {
      const w = window as unknown as { seenXtool: string[] };
      w.seenXtool = [];
      const look = (): void => {
        const t = document.querySelector('[data-testid="tile-demo-xtool"]')?.textContent ?? '';
        if (w.seenXtool.at(-1) !== t) w.seenXtool.push(t);
      };
      new MutationObserver(look).observe(document.body, {
        subtree: true,
        childList: true,
        characterData: true,
      });
      look();
    });
    // The TouchCut's reads are refused, again and again.
    await expect.poll(() => refused, { timeout: 30_000 }).toBeGreaterThan(3);
    const at = refused;
    await expect.poll(() => refused, { timeout: 30_000 }).toBeGreaterThan(at + 3);
    await page.screenshot({ path: '/tmp/s1-refusal.png' });
    const seen = await page.evaluate(() => (window as unknown as { seenXtool: string[] }).seenXtool);
    expect(seen.length).toBeGreaterThan(0);
    expect(seen.filter((t) => /Reconnecting/i.test(t))).toEqual([]);
    await expect(xtool).not.toContainText('Reconnecting');
    expect(readSockets).toEqual({ opened: 1, closed: 0 });
  });
});
