import http from 'node:http';
import type { AddressInfo } from 'node:net';
import { afterEach, describe, expect, it } from 'vitest';
import type { AuditEntry } from './audit';
import {
  openWs,
  gatewayFor,
  stubEntry,
  stubFor,
  startStub,
  tempDir,
  testFamily,
  type Running,
  type Stub,
  consoleFetch,
  selfSignedCert,
} from './test-util';
import type { MachineEntry } from './machines';

const cleanups: Array<() => Promise<void> | void> = [];
afterEach(async () => {
  for (const c of cleanups.splice(0).reverse()) await c();
});

const entry = stubEntry;

function setup(
  machines: MachineEntry[],
  extra: { timeoutMs?: number; defaultWsPort?: number; allowedHosts?: string[] } = {},
): Promise<Running> {
  return gatewayFor(cleanups, machines, {
    families: { prunt: testFamily('prunt', extra.defaultWsPort) },
    timeoutMs: extra.timeoutMs,
    allowedHosts: extra.allowedHosts,
  });
}

const stub = (): Promise<Stub> => stubFor(cleanups);

function auditOf(gw: Running): AuditEntry[] {
  return gw.gw.audit.all();
}

describe('proxy /machines/<id>/…', () => {
  it('answers 404 with JSON for an id that is not in the file, over HTTP and WebSocket', async () => {
    const s = await stub();
    const gw = await setup([entry('laser-1', s.url)]);
    const r = await consoleFetch(`${gw.url}/machines/laser-2/status`);
    expect(r.status).toBe(404);
    expect(await r.json()).toEqual({ error: 'no machine "laser-2" in the machines file' });
    await expect(openWs(`ws://${gw.host}/machines/laser-2/`)).rejects.toMatchObject({ status: 404 });
    // A malformed id (bad percent-encoding) is just unknown, for HTTP and sockets alike.
    expect((await consoleFetch(`${gw.url}/machines/%E0%A4%A/status`)).status).toBe(404);
    await expect(openWs(`ws://${gw.host}/machines/%E0%A4%A/`)).rejects.toMatchObject({ status: 404 });
    expect((await consoleFetch(`${gw.url}/machines/laser-1/status`)).status).toBe(200);
    expect(s.seen).toHaveLength(1);
  });

  it('forwards method, path, query and body; strips cookies, X-Shopdeck-* and hop-by-hop headers both ways', async () => {
    const s = await stub();
    const gw = await setup([entry('p1', s.url)]);
    const r = await consoleFetch(`${gw.url}/machines/p1/settings?x=1&y=a%20b`, {
      method: 'POST',
      headers: {
        Cookie: 'shopdeck_session=secret-session',
        'X-Shopdeck-Command': 'prunt.save',
        'X-Custom': 'kept',
        'Content-Type': 'application/json',
      },
      body: '{"a":1}',
    });
    expect(r.status).toBe(200);
    expect(r.headers.get('set-cookie')).toBeNull();
    expect(await r.json()).toEqual({ ok: true, path: '/settings?x=1&y=a%20b' });
    expect(s.seen).toHaveLength(1);
    const seen = s.seen[0]!;
    expect(seen.method).toBe('POST');
    expect(seen.body).toBe('{"a":1}');
    expect(seen.headers.cookie).toBeUndefined();
    expect(seen.headers['x-shopdeck-command']).toBeUndefined();
    expect(seen.headers['x-custom']).toBe('kept');
    expect(seen.headers.host).toBe(`127.0.0.1:${s.port}`);
  });

  it('never leaves the configured host, whatever the path looks like', async () => {
    const s = await stub();
    const gw = await setup([entry('p1', s.url)]);
    // A raw request line: consoleFetch() would normalize these paths itself.
    for (const raw of [
      '/machines/p1//evil.example/x',
      '/machines/p1/../../api/x',
      '/machines/p1/%2e%2e/%2e%2e/y',
    ]) {
      const status = await new Promise<number>((resolve, reject) => {
        const req = http.request(
          { host: '127.0.0.1', port: Number(gw.host.split(':')[1]), path: raw },
          (res) => {
            res.resume();
            resolve(res.statusCode ?? 0);
          },
        );
        req.on('error', reject);
        req.end();
      });
      expect(status).toBe(200);
    }
    expect(s.seen.map((x) => x.url)).toEqual(['/evil.example/x', '/api/x', '/y']);
  });

  it('classifies the canonical path, so an encoded path cannot dodge a rule', async () => {
    const s = await stub();
    const gw = await setup([entry('p1', s.url)]);
    await consoleFetch(`${gw.url}/machines/p1/%6Aob?action=stop`, {
      headers: { 'X-Shopdeck-Command': 'test.stop' },
    });
    expect(s.seen[0]?.url).toBe('/job?action=stop');
    const a = auditOf(gw);
    expect(a).toHaveLength(1);
    expect(a[0]).toMatchObject({
      type: 'command',
      machine: 'p1',
      method: 'GET',
      path: '/job?action=stop',
      commandId: 'test.stop',
      status: 200,
      result: 'ok',
      user: 'anonymous',
    });
    const dup = await consoleFetch(`${gw.url}/machines/p1/job?action=status&action=stop`);
    expect(dup.status).toBe(400);
    expect(s.seen).toHaveLength(1);
  });

  it('audits every non-GET and every GET the family marks as a command, with the controller status', async () => {
    const s = await stub();
    s.respond = (req, res) => {
      res.writeHead(req.url?.startsWith('/settings') ? 409 : 200, { 'Content-Type': 'application/json' });
      res.end('{}');
    };
    const gw = await setup([entry('p1', s.url)]);
    await consoleFetch(`${gw.url}/machines/p1/status`);
    await consoleFetch(`${gw.url}/machines/p1/job?action=pause`, {
      headers: { 'X-Shopdeck-Command': 'test.pause' },
    });
    await consoleFetch(`${gw.url}/machines/p1/settings`, {
      method: 'POST',
      body: 'x=1',
      headers: { 'X-Shopdeck-Command': 'test.save' },
    });
    const a = auditOf(gw);
    // commandId: what the gateway classified; clientCommand: the page's own name, a label only.
    expect(a.map((e) => [e.commandId, e.clientCommand, e.path, e.status, e.result])).toEqual([
      ['test.pause', 'test.pause', '/job?action=pause', 200, 'ok'],
      [undefined, 'test.save', '/settings', 409, 'error'],
    ]);
    const api = (await (await consoleFetch(`${gw.url}/api/audit?limit=1`)).json()) as {
      entries: AuditEntry[];
      total: number;
    };
    expect(api.total).toBe(2);
    expect(api.entries[0]?.clientCommand).toBe('test.save');
  });

  it('answers 504 with JSON when the controller does not answer in time, and audits the error', async () => {
    const s = await stub();
    s.respond = () => undefined; // never answers
    const gw = await setup([entry('p1', s.url)], { timeoutMs: 200 });
    const r = await consoleFetch(`${gw.url}/machines/p1/settings`, { method: 'POST', body: '1' });
    expect(r.status).toBe(504);
    expect(((await r.json()) as { error: string }).error).toMatch(/did not answer within 200 ms/);
    expect(auditOf(gw)[0]).toMatchObject({ result: 'error', machine: 'p1' });
  });

  it('answers 502 when the controller is unreachable', async () => {
    const closed = http.createServer();
    await new Promise<void>((r) => closed.listen(0, '127.0.0.1', () => r()));
    const port = (closed.address() as AddressInfo).port;
    await new Promise<void>((r) => closed.close(() => r()));
    const gw = await setup([entry('p1', `http://127.0.0.1:${port}`)]);
    const r = await consoleFetch(`${gw.url}/machines/p1/status`);
    expect(r.status).toBe(502);
    const error = ((await r.json()) as { error: string }).error;
    expect(error).toMatch(/p1 refused the connection/);
    // Words for the operator, never the controller's address; marked as the gateway's own error.
    expect(error).not.toContain('127.0.0.1');
    expect(error).not.toContain(String(port));
    expect(r.headers.get('x-shopdeck-gateway')).toBe('error');
  });

  it('reaches a controller with a self-signed HTTPS certificate', async () => {
    const t = tempDir();
    cleanups.push(t.cleanup);
    const { key, cert } = selfSignedCert(t.dir, 'kineticcutter');
    const s = await startStub({ key, cert });
    cleanups.push(s.close);
    // Node's own fetch refuses it: the certificate is really self-signed.
    await expect(consoleFetch(`${s.url}/status`)).rejects.toThrow();
    const gw = await setup([entry('plasma', s.url)]);
    const r = await consoleFetch(`${gw.url}/machines/plasma/status`);
    expect(r.status, await r.clone().text()).toBe(200);
    expect(await r.json()).toEqual({ ok: true, path: '/status' });
    const w = await openWs(`ws://${gw.host}/machines/plasma/live`);
    expect(w.first).toBe('hello');
    await w.close();
  });

  it('proxies WebSockets both ways to wsUrl, or to the family default port on the url host', async () => {
    const s = await stub();
    const other = await stub();
    const gw = await setup(
      [entry('a', s.url, { wsUrl: new URL(other.wsUrl + '/base') }), entry('b', 'http://127.0.0.1:9/x')],
      { defaultWsPort: s.port },
    );
    const a = await openWs(`ws://${gw.host}/machines/a/live?x=1`, { Cookie: 'shopdeck_session=zzz' });
    expect(a.first).toBe('hello');
    a.ws.send('ping');
    expect(await a.next()).toBe('echo:ping');
    await a.close();
    expect(other.wsSeen[0]?.url).toBe('/base/live?x=1');
    expect(other.wsSeen[0]?.headers.cookie).toBeUndefined();
    const b = await openWs(`ws://${gw.host}/machines/b/`);
    expect(b.first).toBe('hello');
    await b.close();
    expect(s.wsSeen[0]?.url).toBe('/x/');
  });

  it('injects secrets and never lets them reach the browser', async () => {
    const s = await stub();
    s.respond = (req, res) => {
      // A controller that echoes what it got, secret included.
      res.writeHead(200, { 'Content-Type': 'application/json', 'X-Echo': String(req.headers['x-api-key']) });
      res.end(JSON.stringify({ key: req.headers['x-api-key'], url: req.url }));
    };
    const secrets = { apiKey: '13F513776F764DA5B5F0', password: 'hunter2hunter2' };
    const gw = await setup([entry('cut', s.url, { secrets })]);
    const list = await (await consoleFetch(`${gw.url}/api/machines`)).text();
    expect(JSON.parse(list)).toEqual({
      machines: [{ id: 'cut', name: 'cut', kind: 'prunt', simulated: false }],
      demo: false,
    });
    expect(list).not.toContain(secrets.apiKey);
    const r = await consoleFetch(`${gw.url}/machines/cut/login`);
    const text = await r.text();
    expect(s.seen[0]?.headers['x-api-key']).toBe(secrets.apiKey);
    expect(s.seen[0]?.url).toBe(`/login?password=${secrets.password}`);
    expect(text).not.toContain(secrets.apiKey);
    expect(text).not.toContain(secrets.password);
    expect(text).toContain('[redacted]');
    expect(r.headers.get('x-echo')).toBe('[redacted]');
  });

  it('answers simulated machines from an in-process simulator, with access rules and audit', async () => {
    const gw = await setup([entry('demo', null, { simulated: true })]);
    const r = await consoleFetch(`${gw.url}/machines/demo/job?action=pause`, {
      headers: { 'X-Shopdeck-Command': 'test.pause' },
    });
    expect(await r.json()).toMatchObject({ sim: 'demo', path: '/job', action: 'pause' });
    expect(auditOf(gw)[0]).toMatchObject({ machine: 'demo', commandId: 'test.pause', status: 200 });
    const w = await openWs(`ws://${gw.host}/machines/demo/live`);
    expect(w.first).toBe('sim-hello 1');
    w.ws.send('x');
    expect(await w.next()).toBe('sim-echo:x');
    await w.close();
  });

  it('takes no audit records from the browser: simulated machines are audited by the gateway', async () => {
    const gw = await setup([entry('demo', null, { simulated: true })]);
    const r = await consoleFetch(`${gw.url}/api/audit/client`, {
      method: 'POST',
      headers: { 'Content-Type': 'application/json' },
      body: JSON.stringify({ machine: 'demo', command: 'test.pause', label: 'Pause', ok: true }),
    });
    expect(r.status).toBe(404);
    expect(auditOf(gw)).toEqual([]);
  });

  it('refuses host names it was not configured for (DNS rebinding), HTTP and WebSocket', async () => {
    const s = await stub();
    const gw = await setup([entry('p1', s.url)], { allowedHosts: ['.shop.example'] });
    const port = Number(gw.host.split(':')[1]);
    const status = (host: string, upgrade = false) =>
      new Promise<number>((resolve, reject) => {
        const req = http.request({
          host: '127.0.0.1',
          port,
          path: '/machines/p1/status',
          headers: upgrade
            ? {
                Host: host,
                Origin: `http://${host}`,
                Connection: 'Upgrade',
                Upgrade: 'websocket',
                'Sec-WebSocket-Version': '13',
                'Sec-WebSocket-Key': 'dGhlIHNhbXBsZSBub25jZQ==',
              }
            : { Host: host },
        });
        req.on('response', (res) => {
          res.resume();
          resolve(res.statusCode ?? 0);
        });
        req.on('upgrade', (res, socket) => {
          socket.destroy();
          resolve(res.statusCode ?? 0);
        });
        req.on('error', reject);
        req.end();
      });
    expect(await status('attacker.example:80')).toBe(403);
    expect(await status('attacker.example:80', true)).toBe(403);
    expect(await status('console.shop.example')).toBe(200);
    expect(await status(`localhost:${port}`)).toBe(200);
    expect(await status(`127.0.0.1:${port}`, true)).toBe(101);
    expect(s.seen).toHaveLength(2);
  });

  it('keeps redirects of the controller under /machines/<id>', async () => {
    const s = await stub();
    s.respond = (req, res) => {
      const to: Record<string, string> = {
        '/a': `${s.url}/base/next?x=1`,
        '/b': '/base/abs',
        '/c': 'relative/page',
        '/d': 'http://elsewhere.example/x',
      };
      res.writeHead(302, { Location: to[String(req.url).replace('/base', '')] ?? '/' });
      res.end();
    };
    const gw = await setup([entry('p1', `${s.url}/base`)]);
    const loc = async (p: string) =>
      (await consoleFetch(`${gw.url}/machines/p1${p}`, { redirect: 'manual' })).headers.get('location');
    expect(await loc('/a')).toBe('/machines/p1/next?x=1');
    expect(await loc('/b')).toBe('/machines/p1/abs');
    // Relative redirects resolve on the controller, so they cannot climb to another machine.
    expect(await loc('/c')).toBe('/machines/p1/relative/page');
    // A redirect to another site is refused (502 from the gateway, no Location).
    const away = await consoleFetch(`${gw.url}/machines/p1/d`, { redirect: 'manual' });
    expect(away.status).toBe(502);
    expect(away.headers.get('location')).toBeNull();
    expect(s.seen.map((x) => x.url)).toEqual(['/base/a', '/base/b', '/base/c', '/base/d']);
  });
});
