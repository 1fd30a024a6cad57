import { spawn, type ChildProcess } from 'node:child_process';
import { mkdtempSync, rmSync, writeFileSync } from 'node:fs';
import http, { type IncomingMessage } from 'node:http';
import { createServer, type AddressInfo } from 'node:net';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import { expect, test } from '@playwright/test';
import { WebSocketServer } from 'ws';

/**
 * The trust boundary attacked from a real browser: a hostile page served from another site
 * (localhost vs 127.0.0.1) and from another port of the console's own host, against the real
 * gateway (vite preview, open mode, which is the easiest to attack) in front of a stub laser
 * controller that records every request and socket that reaches it.
 */

let dir = '';
let gw = '';
let gwHost = '';
let attackPort = 0;
const children: ChildProcess[] = [];
const reached: string[] = [];
const sockets: string[] = [];
let controller: http.Server | null = null;
let attacker: http.Server | null = null;

function freePort(): Promise<number> {
  return new Promise((resolve) => {
    const s = createServer();
    s.listen(0, '127.0.0.1', () => {
      const p = (s.address() as AddressInfo).port;
      s.close(() => resolve(p));
    });
  });
}

function attackPage(kind: string): string {
  const machine = `${gw}/machines/laser`;
  switch (kind) {
    case 'img':
      // What any web page can do without script: a GET command in an image, and a frame.
      return `<!doctype html><title>cats</title>
        <img src="${machine}/cnc/data?action=pause">
        <img src="${machine}/cnc/data?action=stop">
        <script>
          fetch('${machine}/cnc/data?action=stop', { mode: 'no-cors', credentials: 'include' });
          fetch('${machine}/cnc/data?action=pause', { method: 'POST', mode: 'no-cors', credentials: 'include', body: 'x' });
          fetch('${machine}/cnc/data?action=pause', { credentials: 'include', headers: { 'X-Shopdeck': '1' } }).catch(() => {});
          try { new WebSocket('ws://${gwHost}/machines/laser/'); } catch (e) {}
        </script>`;
    case 'form':
      return `<!doctype html><form id="f" method="POST" action="${machine}/cnc/data?action=pause">
        <input name="x" value="1"></form><script>document.getElementById('f').submit()</script>`;
    case 'frame':
      return `<!doctype html><title>framed</title><iframe id="f" src="${gw}/" width="800" height="600"></iframe>`;
    default:
      return 'nothing';
  }
}

test.describe.configure({ mode: 'serial' });

test.describe('attacks on the gateway from a browser', () => {
  test.beforeAll(async ({}, info) => {
    if (info.project.name !== 'desktop') return;
    dir = mkdtempSync(join(tmpdir(), 'shopdeck-attacks-'));
    // The stub laser: records everything; answers its status, and markup where asked.
    controller = http.createServer((req: IncomingMessage, res) => {
      reached.push(`${req.method} ${req.url}`);
      if ((req.url ?? '').startsWith('/system?action=get_dev_name')) {
        // A device name set to markup, answered as text/html as the xTool answers everything.
        res.writeHead(200, { 'Content-Type': 'text/html' });
        res.end('<h1>device</h1><script>alert(document.domain)</script>');
        return;
      }
      res.writeHead(200, { 'Content-Type': 'text/html' }); // as the xTool does for JSON
      res.end('{"result":"ok"}');
    });
    const wss = new WebSocketServer({ server: controller });
    wss.on('connection', (_ws, req) => sockets.push(req.url ?? ''));
    await new Promise<void>((r) => controller?.listen(0, '127.0.0.1', () => r()));
    const cport = (controller.address() as AddressInfo).port;
    writeFileSync(
      join(dir, 'machines.json'),
      JSON.stringify({
        machines: [
          {
            id: 'laser',
            name: 'Laser',
            kind: 'xtool',
            url: `http://127.0.0.1:${cport}`,
            wsUrl: `ws://127.0.0.1:${cport}`,
          },
        ],
      }),
    );
    const port = await freePort();
    gw = `http://127.0.0.1:${port}`;
    gwHost = `127.0.0.1:${port}`;
    const c = spawn(
      process.execPath,
      [
        'node_modules/vite/bin/vite.js',
        'preview',
        '--port',
        String(port),
        '--strictPort',
        '--host',
        '127.0.0.1',
      ],
      {
        env: {
          ...process.env,
          SHOPDECK_MACHINES: join(dir, 'machines.json'),
          SHOPDECK_DATA: join(dir, 'data'),
          SHOPDECK_USERS: join(dir, 'no-users.json'),
        },
        stdio: ['ignore', 'pipe', 'pipe'],
        detached: true,
      },
    );
    c.stdout?.resume();
    c.stderr?.resume();
    children.push(c);
    for (let i = 0; i < 240; i++) {
      try {
        if ((await fetch(`${gw}/api/session`)).status < 500) break;
      } catch {
        // not up yet
      }
      await new Promise((r) => setTimeout(r, 250));
    }
    // The attacker's server: reachable as http://localhost:<port> (another site) and as
    // http://127.0.0.1:<port> (another port of the console's own host: the same site).
    attacker = http.createServer((req, res) => {
      const kind = new URL(req.url ?? '/', 'http://x').searchParams.get('kind') ?? '';
      res.writeHead(200, { 'Content-Type': 'text/html' });
      res.end(attackPage(kind));
    });
    await new Promise<void>((r) => attacker?.listen(0, '127.0.0.1', () => r()));
    attackPort = (attacker.address() as AddressInfo).port;
  });

  test.afterAll(async () => {
    for (const c of children) {
      if (c.pid && c.exitCode === null) {
        try {
          process.kill(-c.pid, 'SIGTERM');
        } catch {
          c.kill('SIGTERM');
        }
      }
    }
    await new Promise<void>((r) => (controller ? controller.close(() => r()) : r()));
    await new Promise<void>((r) => (attacker ? attacker.close(() => r()) : r()));
    if (dir) rmSync(dir, { recursive: true, force: true });
  });

  test.beforeEach(({}, info) => {
    test.skip(info.project.name !== 'desktop', 'one run is enough: it starts its own gateway');
    reached.length = 0;
    sockets.length = 0;
  });

  for (const [where, host] of [
    ['another site', 'localhost'],
    ['another port of the same host', '127.0.0.1'],
  ] as const) {
    test(`4: a page on ${where} cannot send a GET command, a POST or open a socket`, async ({ browser }) => {
      const ctx = await browser.newContext();
      // The console is open in the same browser (its cookies, if any, would be sent).
      const consolePage = await ctx.newPage();
      await consolePage.goto(`${gw}/`);
      await expect(consolePage.getByRole('link', { name: /Laser/ }).first()).toBeVisible();
      const page = await ctx.newPage();
      await page.goto(`http://${host}:${attackPort}/?kind=img`);
      await page.waitForTimeout(1500);
      const form = await ctx.newPage();
      await form.goto(`http://${host}:${attackPort}/?kind=form`);
      await form.waitForLoadState('load');
      await page.waitForTimeout(500);
      const commands = reached.filter((r) => /action=(pause|stop)/.test(r) || r.startsWith('POST'));
      expect(commands).toEqual([]);
      // The only socket the laser saw is the console's own.
      expect(sockets.length).toBeLessThanOrEqual(1);
      await ctx.close();
    });

    test(`12: a page on ${where} cannot frame the console`, async ({ browser }) => {
      const ctx = await browser.newContext();
      const page = await ctx.newPage();
      const blocked = page.waitForEvent('console', {
        predicate: (m) => /frame-ancestors|X-Frame-Options|refused to (display|frame)/i.test(m.text()),
        timeout: 10_000,
      });
      await page.goto(`http://${host}:${attackPort}/?kind=frame`);
      await blocked;
      await page.waitForTimeout(1000);
      // Had the console loaded in the frame, it would have asked the laser who it is and its
      // status. The gateway's own watch polls the working state every 10 s with no page at all:
      // that one read is not the frame's.
      expect(reached.filter((r) => r !== 'GET /system?action=get_working_sta')).toEqual([]);
      const frame = page.frames().find((f) => f !== page.mainFrame());
      const text = frame ? await frame.evaluate(() => document.body?.innerText ?? '').catch(() => '') : '';
      expect(text).not.toMatch(/Shopdeck|Laser/);
      await ctx.close();
    });
  }

  test('2: markup from a controller is shown as text, never run on the console origin', async ({ page }) => {
    let dialogs = 0;
    page.on('dialog', (d) => {
      dialogs++;
      void d.dismiss();
    });
    const res = await page.goto(`${gw}/machines/laser/system?action=get_dev_name`);
    expect(res?.headers()['content-type']).toMatch(/^text\/plain/);
    expect(res?.headers()['content-security-policy']).toContain('sandbox');
    await page.waitForTimeout(500);
    expect(dialogs).toBe(0);
    // Shown as the text it is.
    await expect(page.locator('body')).toContainText('<script>alert(document.domain)</script>');
  });
});

test.describe('the console under its own Content-Security-Policy', () => {
  test('no page of the demo fleet reports a CSP violation', async ({ page }) => {
    const violations: string[] = [];
    page.on('console', (m) => {
      if (/Content Security Policy|Refused to (load|execute|apply|connect|frame)/i.test(m.text()))
        violations.push(m.text());
    });
    await page.addInitScript(() => {
      document.addEventListener('securitypolicyviolation', (e) =>
        console.error(`Content Security Policy violation: ${e.violatedDirective} ${e.blockedURI}`),
      );
    });
    const res = await page.goto('/');
    expect(res?.headers()['content-security-policy']).toContain("frame-ancestors 'none'");
    await expect(page.getByTestId('tile-demo-xtool')).toBeVisible();
    for (const id of ['demo-xtool', 'demo-touchcut', 'demo-duet', 'demo-prunt', 'demo-g2core']) {
      await page.goto(`/m/${id}`);
      await expect(page.getByTestId('machine-link')).toBeVisible();
      await page.waitForTimeout(300);
    }
    expect(violations).toEqual([]);
  });
});
