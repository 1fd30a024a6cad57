import http from 'node:http';
import net, { type AddressInfo } from 'node:net';
import path from 'node:path';
import { afterEach, describe, expect, it } from 'vitest';
import {
  consoleFetch,
  login,
  startGateway,
  startStub,
  stubEntry,
  tempDir,
  testFamily,
  user,
  writeJson,
  type Cleanups,
} from './test-util';

/**
 * Finding 14 of the pen test, performed against the real gateway on real sockets: a supervisor's
 * alarm webhook pointed at what the gateway guards (the machines, this computer, link-local
 * addresses) to reach them or scan them through the "send a test" answer. Each target must be
 * refused before one byte is sent, and the answer must say nothing but "failed".
 */

const cleanups: Cleanups = [];
afterEach(async () => {
  for (const c of cleanups.splice(0).reverse()) await c();
});

/** A TCP listener that counts connections (HTTP or not): did the gateway connect at all? */
async function listener(host: string): Promise<{ port: number; connections: () => number } | null> {
  let n = 0;
  const server = net.createServer((s) => {
    n++;
    s.destroy();
  });
  const ok = await new Promise<boolean>((r) => {
    server.once('error', () => r(false));
    server.listen(0, host, () => r(true));
  });
  if (!ok) return null; // no IPv6 loopback on this computer
  cleanups.push(() => new Promise<void>((r) => server.close(() => r())));
  return { port: (server.address() as AddressInfo).port, connections: () => n };
}

/** A webhook receiver that records what it is sent. */
async function receiver(): Promise<{ port: number; got: unknown[] }> {
  const got: unknown[] = [];
  const server = http.createServer((req, res) => {
    let text = '';
    req.on('data', (c: Buffer) => (text += c.toString()));
    req.on('end', () => {
      got.push(JSON.parse(text));
      res.writeHead(204);
      res.end();
    });
  });
  await new Promise<void>((r) => server.listen(0, '127.0.0.1', () => r()));
  cleanups.push(
    () =>
      new Promise<void>((r) => {
        server.closeAllConnections();
        server.close(() => r());
      }),
  );
  return { port: (server.address() as AddressInfo).port, got };
}

describe('the alarm webhook is not a port scanner (finding 14)', () => {
  it('refuses loopback, link-local and the machines’ own hosts before connecting; the answer says only "failed"', async () => {
    const stub = await startStub();
    cleanups.push(stub.close);
    const v4 = await listener('127.0.0.1');
    const v6 = await listener('::1');
    const allowed = await receiver();
    if (!v4) throw new Error('no IPv4 loopback');
    const t = tempDir();
    cleanups.push(t.cleanup);
    const usersFile = writeJson(path.join(t.dir, 'users.json'), {
      users: [user('sam', 'supervisor', 'sam-pass-1'), user('otto', 'operator', 'otto-pass-1')],
    });
    // The server's settings file allows one receiver on this computer, by host and port.
    writeJson(path.join(t.dir, 'settings.json'), { webhookAllowHosts: [`127.0.0.1:${allowed.port}`] });
    const gw = await startGateway({
      machines: {
        file: null,
        machines: [
          stubEntry('duet', stub.url),
          // A machine known by a name (never resolved here: refused by its name).
          stubEntry('xtool', 'http://xtool-laser.invalid:8080'),
        ],
      },
      families: { prunt: testFamily('prunt') },
      dataDir: t.dir,
      usersFile,
      env: {},
    });
    cleanups.push(gw.close);
    const sam = await login(gw.url, 'sam', 'sam-pass-1');
    const attempt = async (url: string): Promise<unknown> => {
      const put = await consoleFetch(`${gw.url}/api/settings`, {
        method: 'PUT',
        headers: { cookie: sam, 'Content-Type': 'application/json' },
        body: JSON.stringify({ alarmWebhook: url }),
      });
      expect(put.status, url).toBe(200);
      const test = await consoleFetch(`${gw.url}/api/settings/test-webhook`, {
        method: 'POST',
        headers: { cookie: sam },
      });
      expect(test.status).toBe(200);
      return test.json();
    };
    const targets = [
      `http://127.0.0.1:${v4.port}/`,
      `http://127.1:${v4.port}/x`,
      `http://localhost:${v4.port}/`,
      `http://[::ffff:127.0.0.1]:${v4.port}/`,
      `http://[::1]:${v6?.port ?? 9}/`,
      'http://169.254.169.254/latest/meta-data/',
      'http://[fe80::1]/',
      'http://0.0.0.0:9/',
      // The machines' own controllers: the xTool's stop, the Duet's G-code endpoint.
      `${stub.url}/machine/code`,
      'http://xtool-laser.invalid:8080/cnc/data?action=stop',
      'http://XTOOL-LASER.invalid./cnc/data?action=stop',
      // Another port of this computer that is allowed on one port only.
      `http://127.0.0.1:${allowed.port + 1 === v4.port ? allowed.port + 2 : allowed.port + 1}/`,
    ];
    for (const url of targets) expect(await attempt(url), url).toEqual({ ok: false, result: 'failed' });
    // Nothing reached any of them.
    expect(v4.connections()).toBe(0);
    expect(v6?.connections() ?? 0).toBe(0);
    expect(stub.seen).toEqual([]);
    // The reason is in the server's log only… not in the settings page's answer either.
    const settings = await consoleFetch(`${gw.url}/api/settings`, { headers: { cookie: sam } });
    expect(await settings.text()).not.toMatch(/refused|ECONNREFUSED|link-local|machine/);
    // The host the settings file allows works.
    expect(await attempt(`http://127.0.0.1:${allowed.port}/hook/secret`)).toEqual({
      ok: true,
      result: 'delivered',
    });
    expect(allowed.got).toHaveLength(1);
    expect(allowed.got[0]).toMatchObject({ source: 'shopdeck', event: 'test' });
    // An operator cannot test it at all.
    const otto = await login(gw.url, 'otto', 'otto-pass-1');
    const op = await consoleFetch(`${gw.url}/api/settings/test-webhook`, {
      method: 'POST',
      headers: { cookie: otto },
    });
    expect(op.status).toBe(403);
  });
});
