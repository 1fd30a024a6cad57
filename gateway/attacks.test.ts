import { gzipSync } from 'node:zlib';
import type { IncomingMessage, ServerResponse } from 'node:http';
import type { AddressInfo } from 'node:net';
import path from 'node:path';
import { afterEach, describe, expect, it } from 'vitest';
import { WebSocket, WebSocketServer } from 'ws';
import type { MachineEntry } from './machines';
import { openModeExposure } from './plugin';
import {
  consoleFetch,
  login,
  openWs,
  startGateway,
  tempDir,
  testFamily,
  user,
  writeJson,
  type Running,
  type Stub,
  selfSignedCert,
  stubFor,
  stubEntry,
  gatewayFor,
} from './test-util';
import type { UserRecord } from './users';
import { bridgeSockets } from './ws-bridge';

/**
 * The attacks of the trust-boundary review, each performed against the real gateway on real
 * sockets, asserting that nothing reached the controller (or nothing came back to the browser).
 */

const KEY = 'tc-Secret-Key-7f3a9b';
const cleanups: Array<() => Promise<void> | void> = [];
afterEach(async () => {
  for (const c of cleanups.splice(0).reverse()) await c();
});

const entry = stubEntry;
const stub = (): Promise<Stub> => stubFor(cleanups);

/** The test family, declaring Prunt-like help pictures as images the console shows. */
function family() {
  const f = testFamily('prunt');
  return { ...f, gateway: { ...f.gateway, imageAnswer: (p: string) => p.startsWith('/extras/images/') } };
}

function gateway(
  machines: MachineEntry[],
  users: UserRecord[] | null = null,
): Promise<Running & { usersFile: string }> {
  return gatewayFor(cleanups, machines, { users, families: { prunt: family() } });
}

describe('2: a controller answer never renders as a page on the console origin', () => {
  it('serves markup as text, sandboxed, and keeps images only where the console shows them', async () => {
    const s = await stub();
    s.respond = (req, res) => {
      const answers: Record<string, [string, string]> = {
        '/system': ['text/html', '{"name":"<img src=x onerror=alert(document.cookie)>"}'],
        '/pic.svg': [
          'image/svg+xml',
          '<svg xmlns="http://www.w3.org/2000/svg"><script>alert(1)</script></svg>',
        ],
        '/feed': [
          'application/xhtml+xml',
          '<html xmlns="http://www.w3.org/1999/xhtml"><script>1</script></html>',
        ],
        '/data': ['application/json', '{"ok":true}'],
        '/extras/images/stepper_1.png': ['image/png', 'PNG'],
        '/other.png': ['image/png', 'PNG'],
        '/nothing': ['', 'x'],
      };
      const [type, body] = answers[req.url ?? ''] ?? ['text/plain', ''];
      res.writeHead(200, {
        ...(type ? { 'Content-Type': type } : {}),
        'Access-Control-Allow-Origin': '*',
        'Strict-Transport-Security': 'max-age=31536000',
        'Clear-Site-Data': '"cookies", "storage"',
        Refresh: '0; url=http://evil.example/',
        Link: '<http://evil.example/x.js>; rel=preload',
      });
      res.end(body);
    };
    const gw = await gateway([entry('p1', s.url)]);
    const get = (p: string) => consoleFetch(`${gw.url}/machines/p1${p}`);
    for (const p of ['/system', '/pic.svg', '/feed']) {
      const r = await get(p);
      expect(r.headers.get('content-type'), p).toMatch(/^text\/plain/);
    }
    for (const p of ['/system', '/data', '/extras/images/stepper_1.png', '/other.png', '/nothing']) {
      const r = await get(p);
      expect(r.headers.get('content-security-policy'), p).toContain('sandbox');
      expect(r.headers.get('content-security-policy'), p).toContain("default-src 'none'");
      expect(r.headers.get('x-content-type-options'), p).toBe('nosniff');
      for (const h of [
        'access-control-allow-origin',
        'strict-transport-security',
        'clear-site-data',
        'refresh',
        'link',
      ])
        expect(r.headers.get(h), `${p} ${h}`).toBeNull();
    }
    expect((await get('/data')).headers.get('content-type')).toBe('application/json');
    // The Prunt family declares its help pictures: an image there, a download anywhere else.
    expect((await get('/extras/images/stepper_1.png')).headers.get('content-type')).toBe('image/png');
    expect((await get('/other.png')).headers.get('content-type')).toBe('application/octet-stream');
    expect((await get('/nothing')).headers.get('content-type')).toBe('application/octet-stream');
  });
});

describe('4: commands and sockets must prove they come from the console', () => {
  it('refuses an <img> GET command from another site or another port, in open mode', async () => {
    const s = await stub();
    const gw = await gateway([entry('p1', s.url)]);
    const stop = `${gw.url}/machines/p1/job?action=stop`;
    // What a browser sends for <img src> on another site, and on another port of this host.
    for (const site of ['cross-site', 'same-site']) {
      const r = await fetch(stop, { headers: { 'Sec-Fetch-Site': site, 'Sec-Fetch-Dest': 'image' } });
      expect(r.status, site).toBe(403);
    }
    // No Sec-Fetch-Site (an old browser, a script): the console header is still missing.
    expect((await fetch(stop)).status).toBe(403);
    // A form POST from another origin, and one with a forged console header but another Origin.
    expect((await fetch(`${gw.url}/machines/p1/settings`, { method: 'POST', body: 'x=1' })).status).toBe(403);
    const forged = await fetch(`${gw.url}/machines/p1/settings`, {
      method: 'POST',
      headers: { 'X-Shopdeck': '1', Origin: 'http://127.0.0.1:1' },
      body: 'x=1',
    });
    expect(forged.status).toBe(403);
    expect(s.seen).toHaveLength(0);
    // The console itself gets through, and a plain read from a bookmark too.
    expect((await consoleFetch(stop, { headers: { 'Sec-Fetch-Site': 'same-origin' } })).status).toBe(200);
    expect(
      (await fetch(`${gw.url}/machines/p1/status`, { headers: { 'Sec-Fetch-Site': 'none' } })).status,
    ).toBe(200);
    expect(s.seen.map((x) => x.url)).toEqual(['/job?action=stop', '/status']);
    const refused = gw.gw.audit.all().filter((e) => e.type === 'refused');
    expect(refused.length).toBeGreaterThanOrEqual(4);
  });

  it('refuses API writes (login, logout, elevation) without the console header', async () => {
    const gw = await gateway([], [user('sam', 'supervisor', 'pw-sam-1')]);
    const r = await fetch(`${gw.url}/api/login`, {
      method: 'POST',
      headers: { 'Content-Type': 'text/plain' },
      body: JSON.stringify({ name: 'sam', password: 'pw-sam-1' }),
    });
    expect(r.status).toBe(403);
    expect(r.headers.getSetCookie()).toHaveLength(0);
  });

  it('refuses WebSocket upgrades from another origin, another port, or without an Origin', async () => {
    const s = await stub();
    const gw = await gateway([entry('p1', s.url)]);
    const url = `ws://${gw.host}/machines/p1/live`;
    const port = Number(gw.host.split(':')[1]);
    for (const origin of ['http://evil.example', `http://127.0.0.1:${port + 1}`, 'null']) {
      await expect(openWs(url, { Origin: origin })).rejects.toMatchObject({ status: 403 });
    }
    await expect(
      new Promise((resolve, reject) => {
        const ws = new WebSocket(url); // the ws package sends no Origin
        ws.once('unexpected-response', (_q, res) => resolve(res.statusCode));
        ws.once('open', () => reject(new Error('opened')));
        ws.once('error', reject);
      }),
    ).resolves.toBe(403);
    expect(s.wsSeen).toHaveLength(0);
    const ok = await openWs(url);
    expect(ok.first).toBe('hello');
    await ok.close();
  });
});

describe('8: no secret reaches the browser, whatever the encoding', () => {
  it('redacts binary, gzip, large, hex and chunk-split answers, and leaves other bytes alone', async () => {
    const s = await stub();
    const big = Buffer.concat([Buffer.alloc(3 * 1024 * 1024, 0x41), Buffer.from(KEY)]);
    const notUtf8 = Buffer.from([0xff, 0xfe, 0x00, 0x80, 0x41, 0xc3]);
    s.respond = (req, res) => {
      switch (req.url) {
        case '/bin':
          res.writeHead(200, { 'Content-Type': 'application/octet-stream' });
          res.end(Buffer.concat([Buffer.from([0, 1, 2]), Buffer.from(KEY), Buffer.from([3])]));
          return;
        case '/png':
          res.writeHead(200, { 'Content-Type': 'image/png' });
          res.end(Buffer.from(`\x89PNG${KEY}`, 'latin1'));
          return;
        case '/gz':
          res.writeHead(200, { 'Content-Type': 'application/json', 'Content-Encoding': 'gzip' });
          res.end(gzipSync(`{"key":"${KEY}"}`));
          return;
        case '/big':
          res.writeHead(200, { 'Content-Type': 'text/plain', 'Content-Length': String(big.length) });
          res.end(big);
          return;
        case '/hex':
          res.writeHead(200, { 'Content-Type': 'text/plain' });
          res.end(Buffer.from(KEY).toString('hex'));
          return;
        case '/split': {
          res.writeHead(200, { 'Content-Type': 'text/plain' });
          let i = 0;
          const text = `key=${KEY};`;
          const tick = (): void => {
            if (i >= text.length) {
              res.end();
              return;
            }
            res.write(text[i++]);
            setImmediate(tick);
          };
          tick();
          return;
        }
        case '/latin1':
          res.writeHead(200, { 'Content-Type': 'text/plain; charset=latin1' });
          res.end(notUtf8);
          return;
        default:
          res.writeHead(404);
          res.end();
      }
    };
    const gw = await gateway([entry('p1', s.url, { secrets: { apiKey: KEY } })]);
    const hex = Buffer.from(KEY).toString('hex');
    for (const p of ['/bin', '/png', '/gz', '/big', '/hex', '/split']) {
      const r = await consoleFetch(`${gw.url}/machines/p1${p}`);
      const body = Buffer.from(await r.arrayBuffer());
      expect(body.includes(KEY), p).toBe(false);
      expect(body.toString('latin1').toLowerCase().includes(hex), p).toBe(false);
      expect(body.toString('latin1'), p).toContain('[redacted]');
    }
    const gz = await consoleFetch(`${gw.url}/machines/p1/gz`);
    expect(gz.headers.get('content-encoding')).toBeNull();
    // Never re-encoded: a body without a secret comes through byte for byte.
    const raw = Buffer.from(await (await consoleFetch(`${gw.url}/machines/p1/latin1`)).arrayBuffer());
    expect(raw.equals(notUtf8)).toBe(true);
  });

  it('redacts WebSocket frames', async () => {
    const s = await stub();
    const gw = await gateway([entry('p1', s.url, { secrets: { apiKey: KEY } })]);
    const w = await openWs(`ws://${gw.host}/machines/p1/live`);
    w.ws.send(`my key is ${KEY}`);
    const echoed = await w.next();
    expect(echoed).not.toContain(KEY);
    expect(echoed).toContain('[redacted]');
    await w.close();
  });
});

describe('10: sockets do not outlive their session', () => {
  it('closes a bridged socket on logout, and when the user is removed or demoted', async () => {
    const s = await stub();
    const users = [user('sam', 'supervisor', 'pw-sam-1'), user('vera', 'viewer', 'pw-vera-1')];
    const gw = await gateway([entry('p1', s.url)], users);
    const closedBy = (ws: WebSocket): Promise<number> =>
      new Promise((r) => ws.once('close', (code) => r(code)));

    const cookie = await login(gw.url, 'vera', 'pw-vera-1');
    const a = await openWs(`ws://${gw.host}/machines/p1/live`, { Cookie: cookie });
    const aClosed = closedBy(a.ws);
    await consoleFetch(`${gw.url}/api/logout`, { method: 'POST', headers: { Cookie: cookie } });
    expect(await aClosed).toBe(4401);

    // The supervisor console socket: the user is demoted in the users file (npm run user -- role).
    const samCookie = await login(gw.url, 'sam', 'pw-sam-1');
    const b = await openWs(`ws://${gw.host}/machines/p1/console`, { Cookie: samCookie });
    const bClosed = closedBy(b.ws);
    writeJson(gw.usersFile, { users: [{ ...users[0], role: 'operator' }, users[1]] });
    expect(await bClosed).toBe(4401);

    // Removed.
    const vera = await login(gw.url, 'vera', 'pw-vera-1');
    const c = await openWs(`ws://${gw.host}/machines/p1/live`, { Cookie: vera });
    const cClosed = closedBy(c.ws);
    writeJson(gw.usersFile, { users: [users[0]] });
    expect(await cClosed).toBe(4401);
  });
});

describe('11: a flooding or slow socket is bounded', () => {
  async function pair(): Promise<{
    server: WebSocket;
    client: WebSocket;
    gatewaySide: WebSocket;
    upstream: WebSocket;
    close(): Promise<void>;
  }> {
    // controller <-> [upstream | gateway | gatewaySide] <-> browser
    const ctrl = new WebSocketServer({ port: 0, host: '127.0.0.1' });
    await new Promise<void>((r) => ctrl.once('listening', () => r()));
    const serverP = new Promise<WebSocket>((r) => ctrl.once('connection', r));
    const upstream = new WebSocket(`ws://127.0.0.1:${(ctrl.address() as AddressInfo).port}`);
    const browserSrv = new WebSocketServer({ port: 0, host: '127.0.0.1' });
    await new Promise<void>((r) => browserSrv.once('listening', () => r()));
    const gwSideP = new Promise<WebSocket>((r) => browserSrv.once('connection', r));
    const client = new WebSocket(`ws://127.0.0.1:${(browserSrv.address() as AddressInfo).port}`);
    await Promise.all([
      new Promise((r) => upstream.once('open', r)),
      new Promise((r) => client.once('open', r)),
    ]);
    const [server, gatewaySide] = await Promise.all([serverP, gwSideP]);
    return {
      server,
      client,
      gatewaySide,
      upstream,
      close: async () => {
        for (const ws of [server, client, gatewaySide, upstream]) ws.terminate();
        await new Promise((r) => ctrl.close(r));
        await new Promise((r) => browserSrv.close(r));
      },
    };
  }

  it('passes at most the frame rate a second, pausing the controller, and loses nothing', async () => {
    const p = await pair();
    cleanups.push(p.close);
    bridgeSockets(p.gatewaySide, p.upstream, { limits: { maxFramesPerSecond: 20 } });
    const got: string[] = [];
    p.client.on('message', (d) => got.push(String(d)));
    for (let i = 0; i < 100; i++) p.server.send(`f${i}`);
    await new Promise((r) => setTimeout(r, 300));
    // Within the first second at most one window's worth reached the browser.
    expect(got.length).toBeLessThanOrEqual(20);
    expect(got.length).toBeGreaterThan(0);
    // The rest follow, in order, none dropped.
    await new Promise<void>((resolve) => {
      const t = setInterval(() => {
        if (got.length >= 100) {
          clearInterval(t);
          resolve();
        }
      }, 20);
    });
    expect(got).toEqual(Array.from({ length: 100 }, (_, i) => `f${i}`));
  }, 15_000);

  it('pauses the controller while the browser does not read, instead of buffering', async () => {
    const p = await pair();
    cleanups.push(p.close);
    const b = bridgeSockets(p.gatewaySide, p.upstream, {
      limits: { highWaterBytes: 64 * 1024, maxFramesPerSecond: 10_000 },
    });
    // The browser stops reading its socket.
    (p.client as unknown as { _socket: { pause(): void } })._socket.pause();
    const frame = Buffer.alloc(64 * 1024, 0x61);
    for (let i = 0; i < 200; i++) p.server.send(frame);
    await new Promise((r) => setTimeout(r, 500));
    expect(b.stats.paused).toBeGreaterThan(0);
    // Far less than the 12.8 MB the controller sent waits in the gateway.
    expect(p.gatewaySide.bufferedAmount).toBeLessThan(4 * 1024 * 1024);
  });

  it('closes a socket whose controller sends a frame larger than the bound (1009)', async () => {
    const big = new WebSocketServer({ port: 0, host: '127.0.0.1' });
    await new Promise<void>((r) => big.once('listening', () => r()));
    big.on('connection', (ws) => {
      ws.on('error', () => undefined);
      ws.send(Buffer.alloc(9 * 1024 * 1024));
    });
    cleanups.push(() => new Promise<void>((r) => big.close(() => r())));
    const port = (big.address() as AddressInfo).port;
    const gw = await gateway([entry('p1', `http://127.0.0.1:${port}`)]);
    const ws = new WebSocket(`ws://${gw.host}/machines/p1/live`, { headers: { Origin: gw.url } });
    ws.on('error', () => undefined);
    const code = await new Promise<number>((r) => ws.once('close', (c) => r(c)));
    expect([1006, 1009, 1011]).toContain(code);
  });
});

describe('13: smaller holes', () => {
  it('strips method-override headers before they reach the controller', async () => {
    const s = await stub();
    const gw = await gateway([entry('p1', s.url)]);
    await consoleFetch(`${gw.url}/machines/p1/status`, {
      headers: { 'X-HTTP-Method-Override': 'DELETE', 'X-HTTP-Method': 'PUT', 'X-Method-Override': 'POST' },
    });
    const seen = s.seen[0]?.headers ?? {};
    expect(seen['x-http-method-override']).toBeUndefined();
    expect(seen['x-http-method']).toBeUndefined();
    expect(seen['x-method-override']).toBeUndefined();
  });

  it('open mode refuses to listen on the network unless SHOPDECK_OPEN=1', () => {
    const t = tempDir();
    cleanups.push(t.cleanup);
    const none = path.join(t.dir, 'users.json');
    expect(() => openModeExposure('0.0.0.0', {}, none)).toThrow(/SHOPDECK_OPEN=1/);
    expect(() => openModeExposure(true, {}, none)).toThrow(/open mode/);
    expect(openModeExposure('0.0.0.0', { SHOPDECK_OPEN: '1' }, none)).toBe(true);
    expect(openModeExposure('127.0.0.1', {}, none)).toBe(false);
    expect(openModeExposure('localhost', {}, none)).toBe(false);
    writeJson(none, { users: [user('sam', 'supervisor', 'x')] });
    expect(openModeExposure('0.0.0.0', {}, none)).toBe(false);
  });
});

describe('9: the controller certificate is pinned through the gateway', () => {
  it('an impostor with another self-signed certificate never receives the API key', async () => {
    const https = await import('node:https');
    const t = tempDir();
    cleanups.push(t.cleanup);
    const cert = (name: string): { key: string; cert: string } => selfSignedCert(t.dir, name);
    const real = cert('real');
    const fake = cert('impostor');
    const seen: IncomingMessage['headers'][] = [];
    const handler = (req: IncomingMessage, res: ServerResponse): void => {
      seen.push(req.headers);
      res.writeHead(200, { 'Content-Type': 'application/json' });
      res.end('{"ok":true}');
    };
    let server = https.createServer(real, handler);
    await new Promise<void>((r) => server.listen(0, '127.0.0.1', () => r()));
    const port = (server.address() as AddressInfo).port;
    const gw = await gateway([entry('plasma', `https://127.0.0.1:${port}`, { secrets: { apiKey: KEY } })]);
    // First contact: trusted on first use, pinned.
    expect((await consoleFetch(`${gw.url}/machines/plasma/status`)).status).toBe(200);
    expect(seen).toHaveLength(1);
    // The impostor takes the address with its own certificate.
    await new Promise<void>((r) => server.close(() => r()));
    server = https.createServer(fake, handler);
    await new Promise<void>((r) => server.listen(port, '127.0.0.1', () => r()));
    cleanups.push(() => new Promise<void>((r) => server.close(() => r())));
    const r = await consoleFetch(`${gw.url}/machines/plasma/status`);
    expect(r.status).toBe(502);
    expect(((await r.json()) as { error: string }).error).toMatch(/certificate/i);
    expect(seen).toHaveLength(1);
    // A supervisor sees the pin and, when the controller really was re-keyed, forgets it.
    const list = (await (await consoleFetch(`${gw.url}/api/tls`)).json()) as {
      machines: Array<{ id: string; mode: string; fingerprint: string }>;
    };
    expect(list.machines).toMatchObject([{ id: 'plasma', mode: 'pinned' }]);
    expect(JSON.stringify(list)).not.toContain(String(port));
    expect((await fetch(`${gw.url}/api/tls/plasma`, { method: 'DELETE' })).status).toBe(403);
    expect((await consoleFetch(`${gw.url}/api/tls/plasma`, { method: 'DELETE' })).status).toBe(200);
    expect((await consoleFetch(`${gw.url}/machines/plasma/status`)).status).toBe(200);
    expect(seen).toHaveLength(2);
    expect(gw.gw.audit.all().map((e) => e.type)).toEqual(expect.arrayContaining(['tls-trust', 'tls-forget']));
  }, 20_000);
});

describe('13: credentials in a query never reach the audit log', () => {
  it('a refused connect with a typed password is logged without it', async () => {
    const { auditTarget } = await import('./paths');
    expect(auditTarget({ path: '/machine/connect', rawQuery: 'password=hunter2-secret&x=1' })).toBe(
      '/machine/connect?password=[redacted]&x=1',
    );
    expect(auditTarget({ path: '/machine', rawQuery: 'sessionKey=abc123' })).toBe(
      '/machine?sessionKey=[redacted]',
    );
    expect(auditTarget({ path: '/status', rawQuery: 'filter=%7B%7D' })).toBe('/status?filter=%7B%7D');
    const s = await stub();
    const gw = await gateway([entry('p1', s.url)], [user('vera', 'viewer', 'pw-vera-1', { machines: [] })]);
    const cookie = await login(gw.url, 'vera', 'pw-vera-1');
    const r = await consoleFetch(`${gw.url}/machines/p1/machine/connect?password=hunter2-secret`, {
      headers: { Cookie: cookie },
    });
    expect(r.status).toBe(403);
    expect(JSON.stringify(gw.gw.audit.all())).not.toContain('hunter2-secret');
    expect(s.seen).toHaveLength(0);
  });
});

describe('5 and 7: Duet spellings and G-code through the real gateway', () => {
  it('a viewer cannot read config.g and an operator cannot smuggle a macro past M25', async () => {
    const { duetFamily } = await import('../src/controllers/duet/family');
    const s = await stub();
    s.respond = (req, res) => {
      if ((req.url ?? '').startsWith('/machine/connect')) {
        res.writeHead(200, { 'Content-Type': 'application/json' });
        res.end(
          JSON.stringify({
            sessionKey: 'k-12345678',
            sessionTimeout: 8000,
            isEmulated: false,
            apiVersion: 1,
          }),
        );
        return;
      }
      res.writeHead(200, { 'Content-Type': 'text/plain' });
      res.end('M551 P"machine-password"');
    };
    const t = tempDir();
    cleanups.push(t.cleanup);
    const usersFile = path.join(t.dir, 'users.json');
    writeJson(usersFile, {
      users: [user('vera', 'viewer', 'pw-vera-1'), user('otto', 'operator', 'pw-otto-1')],
    });
    const gw = await startGateway({
      machines: { file: null, machines: [{ ...entry('mk3', s.url), kind: 'duet' }] },
      families: { duet: duetFamily },
      dataDir: t.dir,
      usersFile,
      env: {},
    });
    cleanups.push(gw.close);
    const vera = await login(gw.url, 'vera', 'pw-vera-1');
    for (const p of [
      '/machine/file/sys/config.g',
      '/machine/file/0:%5Csys%5Cconfig.g',
      '/machine/file/%2Fsys%2Fconfig.g',
      '/machine/file/0:sys/config.g',
      '/Machine/File/0:/SYS/CONFIG.G',
      '/machine/file/0:/gcodes/../sys/config.g',
    ]) {
      const r = await consoleFetch(`${gw.url}/machines/mk3${p}`, { headers: { Cookie: vera } });
      expect(r.status, p).toBe(403);
      expect(await r.text(), p).not.toContain('machine-password');
    }
    const otto = await login(gw.url, 'otto', 'pw-otto-1');
    for (const body of [
      'M25 (;) M98 P"evil.g"',
      'M25 (a;b) M562 P0',
      'M25M98 P"evil.g"',
      'M25:M98 P"evil.g"',
      'M25\nM999',
    ]) {
      const r = await consoleFetch(`${gw.url}/machines/mk3/machine/code`, {
        method: 'POST',
        headers: { Cookie: otto, 'Content-Type': 'text/plain' },
        body,
      });
      expect(r.status, body).toBe(403);
    }
    expect(
      s.seen.filter((x) => !x.url.startsWith('/machine/connect') && !x.url.startsWith('/machine/noop')),
    ).toEqual([]);
    // The operator's own job control still passes.
    const ok = await consoleFetch(`${gw.url}/machines/mk3/machine/code`, {
      method: 'POST',
      headers: { Cookie: otto, 'Content-Type': 'text/plain' },
      body: 'M25',
    });
    expect(ok.status).toBe(200);
  });
});
