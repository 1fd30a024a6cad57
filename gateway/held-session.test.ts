import http, { type IncomingHttpHeaders, type IncomingMessage, type ServerResponse } from 'node:http';
import type { AddressInfo } from 'node:net';
import path from 'node:path';
import { afterEach, describe, expect, it } from 'vitest';
import { WebSocket, WebSocketServer } from 'ws';
import { duetFamily } from '../src/controllers/duet/family';
import { DuetSimulator } from '../src/controllers/duet/sim/simulator';
import type { FamilyDescriptor, HeldSessionHooks } from '../src/fleet/contract';
import type { Families } from './context';
import type { MachineEntry } from './machines';
import { login, openWs, startGateway, tempDir, user, writeJson, type Running } from './test-util';

/**
 * The gateway holds the Duet (DSF) session: the browser never sees a session key, whatever it
 * does; every request reaching the controller carries the gateway's key. Real sockets: the real
 * gateway on a plain server, and a DSF stand-in that issues and enforces session keys.
 */

const cleanups: Array<() => Promise<void> | void> = [];
afterEach(async () => {
  for (const c of cleanups.splice(0).reverse()) await c();
});

const PW = 'console-pass-1';

interface Seen {
  method: string;
  url: string;
  headers: IncomingHttpHeaders;
  body: string;
}

interface Dsf {
  url: string;
  port: number;
  seen: Seen[];
  wsSeen: Array<{ url: string; headers: IncomingHttpHeaders }>;
  /** Every key it ever issued. */
  keys: string[];
  valid: Set<string>;
  password: string | null;
  /** Forget every session (DSF restarted / the key expired). */
  expire(): void;
  close(): Promise<void>;
}

const pathOf = (url: string): string => url.split('?')[0] ?? url;
const count = (d: Dsf, p: string): number => d.seen.filter((s) => pathOf(s.url) === p).length;

/** A DSF stand-in: `GET /machine/connect?password=`, `X-Session-Key` on everything else, 403 otherwise. */
async function startDsf(password: string | null = null): Promise<Dsf> {
  const d = { seen: [], wsSeen: [], keys: [], valid: new Set<string>(), password } as unknown as Dsf;
  let n = 0;
  d.expire = () => d.valid.clear();
  const handler = (req: IncomingMessage, res: ServerResponse): void => {
    const chunks: Buffer[] = [];
    req.on('data', (c: Buffer) => chunks.push(c));
    req.on('end', () => {
      const body = Buffer.concat(chunks).toString('utf8');
      d.seen.push({ method: req.method ?? '', url: req.url ?? '', headers: req.headers, body });
      const u = new URL(req.url ?? '/', 'http://dsf');
      // Routes as ASP.NET matches them: decoded, any letter case, empty segments ignored.
      const route = `/${u.pathname
        .split('/')
        .filter(Boolean)
        .map((x) => decodeURIComponent(x).toLowerCase())
        .join('/')}`;
      const password = [...u.searchParams].find(([k]) => k.toLowerCase() === 'password')?.[1] ?? null;
      if (route === '/machine/connect') {
        if (d.password !== null && password !== d.password) {
          res.writeHead(403, { 'Content-Type': 'text/plain' });
          res.end('Invalid password');
          return;
        }
        const key = `dsf-key-${++n}-${Math.random().toString(36).slice(2, 12)}`;
        d.keys.push(key);
        d.valid.add(key);
        res.writeHead(200, { 'Content-Type': 'application/json' });
        res.end(JSON.stringify({ sessionKey: key, apiLevel: 1, isEmulated: false }));
        return;
      }
      const key = req.headers['x-session-key'];
      if (typeof key === 'string' ? !d.valid.has(key) : d.password !== null) {
        res.writeHead(403);
        res.end();
        return;
      }
      if (route === '/machine/disconnect') {
        if (typeof key === 'string') d.valid.delete(key);
        res.writeHead(204);
        res.end();
      } else if (route === '/machine/noop') {
        res.writeHead(204);
        res.end();
      } else if (route === '/machine/echo') {
        // A hostile controller echoing the request: the key must still not reach the browser.
        res.writeHead(200, { 'Content-Type': 'application/json', 'X-Echo': String(key) });
        res.end(JSON.stringify({ headers: req.headers, url: req.url }));
      } else if (route === '/machine/code') {
        res.writeHead(200, { 'Content-Type': 'text/plain' });
        res.end(`ok ${body}`);
      } else {
        res.writeHead(200, { 'Content-Type': 'application/json' });
        res.end(JSON.stringify({ state: { status: 'idle' }, path: u.pathname }));
      }
    });
  };
  const server = http.createServer(handler);
  const wss = new WebSocketServer({
    server,
    verifyClient: (info: { req: IncomingMessage }, cb: (ok: boolean, code?: number) => void) => {
      const key = new URL(info.req.url ?? '/', 'http://dsf').searchParams.get('sessionKey');
      cb(key ? d.valid.has(key) : d.password === null, 403);
    },
  });
  wss.on('connection', (sock, req) => {
    d.wsSeen.push({ url: req.url ?? '', headers: req.headers });
    sock.send(JSON.stringify({ state: { status: 'idle' } }));
    // As DSF: one patch after an acknowledgement when something changed (here: once), and this
    // hostile one echoes the session key it was given in it.
    const key = new URL(req.url ?? '/', 'http://dsf').searchParams.get('sessionKey') ?? '';
    let patched = false;
    sock.on('message', (m) => {
      const text = String(m);
      if (text === 'PING\n') sock.send('PONG\n');
      else if (text === 'OK\n' && !patched) {
        patched = true;
        sock.send(JSON.stringify({ state: { status: 'busy', echo: `key ${key}` } }));
      }
    });
  });
  await new Promise<void>((r) => server.listen(0, '127.0.0.1', () => r()));
  d.port = (server.address() as AddressInfo).port;
  d.url = `http://127.0.0.1:${d.port}`;
  d.close = async () => {
    for (const c of wss.clients) c.terminate();
    await new Promise<void>((r) => wss.close(() => r()));
    server.closeAllConnections();
    await new Promise<void>((r) => server.close(() => r()));
  };
  cleanups.push(d.close);
  return d;
}

interface Setup {
  gw: Running;
  dir: string;
  viewer: string;
  operator: string;
  supervisor: string;
}

async function setup(machines: MachineEntry[], families: Families = { duet: duetFamily }): Promise<Setup> {
  const t = tempDir();
  cleanups.push(t.cleanup);
  const usersFile = writeJson(path.join(t.dir, 'users.json'), {
    users: [user('vic', 'viewer', PW), user('ola', 'operator', PW), user('sue', 'supervisor', PW)],
  });
  const gw = await startGateway({
    machines: { file: null, machines },
    families,
    dataDir: t.dir,
    usersFile,
    env: {},
  });
  cleanups.push(gw.close);
  return {
    gw,
    dir: t.dir,
    viewer: await login(gw.url, 'vic', PW),
    operator: await login(gw.url, 'ola', PW),
    supervisor: await login(gw.url, 'sue', PW),
  };
}

function duet(id: string, d: Dsf | null, extra: Partial<MachineEntry> = {}): MachineEntry {
  return {
    id,
    name: id,
    kind: 'duet',
    // The DSF session mechanics; the probe of a machine without `api` (rr_connect first) is
    // src/controllers/duet/gateway-standalone.test.ts and gateway-standalone.test.ts there.
    api: 'dsf',
    simulated: d === null,
    url: d ? new URL(d.url) : null,
    wsUrl: null,
    secrets: {},
    ...extra,
  };
}

interface Answer {
  status: number;
  /** Every header line as sent. */
  head: string;
  body: Buffer;
  text: string;
}

/** A request with the raw answer (every byte of headers and body), as a browser would send it. */
function send(
  s: Setup,
  method: string,
  p: string,
  cookie: string,
  opts: { headers?: Record<string, string>; body?: string } = {},
): Promise<Answer> {
  const u = new URL(s.gw.url);
  return new Promise((resolve, reject) => {
    const req = http.request(
      {
        host: u.hostname,
        port: u.port,
        method,
        path: p,
        headers: { Cookie: cookie, 'X-Shopdeck': '1', ...opts.headers },
      },
      (res) => {
        const chunks: Buffer[] = [];
        res.on('data', (c: Buffer) => chunks.push(c));
        res.on('end', () => {
          const body = Buffer.concat(chunks);
          resolve({
            status: res.statusCode ?? 0,
            head: res.rawHeaders.join('\n'),
            body,
            text: body.toString('utf8'),
          });
        });
      },
    );
    req.on('error', reject);
    req.end(opts.body);
  });
}

/** No byte the browser got holds any key the controller issued (raw, URL-encoded, base64). */
function expectNoKey(keys: readonly string[], ...got: Array<string | Buffer>): void {
  expect(keys.length).toBeGreaterThan(0);
  for (const g of got) {
    const text = typeof g === 'string' ? g : g.toString('latin1');
    for (const k of keys) {
      for (const form of [k, encodeURIComponent(k), Buffer.from(k).toString('base64')]) {
        expect(text.includes(form), `the browser got a session key (${form})`).toBe(false);
      }
    }
  }
}

function withHooks(patch: Partial<HeldSessionHooks>, streamGraceMs?: number): Families {
  const hooks = duetFamily.gateway?.session;
  if (!hooks) throw new Error('the Duet family does not declare a held session');
  const sharing = duetFamily.gateway?.sharing;
  const fam: FamilyDescriptor = {
    ...duetFamily,
    gateway: {
      ...duetFamily.gateway,
      session: { ...hooks, ...patch },
      // The shared /machine socket closes this long after its last viewer (the family says 10 s).
      ...(sharing && streamGraceMs !== undefined
        ? {
            sharing: { ...sharing, streams: sharing.streams?.map((x) => ({ ...x, graceMs: streamGraceMs })) },
          }
        : {}),
    },
  };
  return { duet: fam };
}

async function until(pred: () => boolean, ms = 5000): Promise<void> {
  const end = Date.now() + ms;
  while (!pred()) {
    if (Date.now() > end) throw new Error('condition not met in time');
    await new Promise((r) => setTimeout(r, 10));
  }
}

describe('held Duet session: the browser never sees a session key', () => {
  it('a viewer’s GET /machine/connect has no session key; M112 cannot be sent around the gateway', async () => {
    const d = await startDsf();
    const s = await setup([duet('mk3', d)]);
    const r = await send(s, 'GET', '/machines/mk3/machine/connect', s.viewer);
    expect(r.status).toBe(200);
    const body = JSON.parse(r.text) as Record<string, unknown>;
    expect(body).not.toHaveProperty('sessionKey');
    // The other fields of the controller's answer stay.
    expect(body).toMatchObject({ apiLevel: 1, isEmulated: false });
    expectNoKey(d.keys, r.head, r.body);
    // The viewer cannot stop the printer through the gateway either.
    const stop = await send(s, 'POST', '/machines/mk3/machine/code', s.viewer, { body: 'M112' });
    expect(stop.status).toBe(403);
    expect(d.seen.filter((x) => x.method === 'POST')).toHaveLength(0);
  });

  it('connect/disconnect in any form ASP.NET routes (case, trailing slash, percent-encoding, method) never reach DSF', async () => {
    const d = await startDsf();
    const s = await setup([duet('mk3', d)]);
    const got: Array<string | Buffer> = [];
    for (const p of ['/Machine/Connect', '/MACHINE/CONNECT/', '/machine/%63onnect', '/machine//connect']) {
      const r = await send(s, 'GET', `/machines/mk3${p}`, s.viewer);
      expect(r.status, p).toBe(200);
      expect(JSON.parse(r.text), p).not.toHaveProperty('sessionKey');
      got.push(r.head, r.body);
    }
    for (const method of ['HEAD', 'POST']) {
      const r = await send(s, method, '/machines/mk3/machine/connect', s.supervisor);
      got.push(r.head, r.body);
    }
    for (const p of ['/Machine/Disconnect', '/machine/disconnect/']) {
      const r = await send(s, 'GET', `/machines/mk3${p}`, s.viewer);
      expect(r.status, p).toBe(204);
    }
    // Only the gateway's own connect reached DSF, and its session is still alive.
    expect(d.seen.map((x) => `${x.method} ${x.url}`)).toEqual(['GET /machine/connect']);
    expect(d.valid.size).toBe(1);
    expectNoKey(d.keys, ...got);
  });

  it('no answer, header or socket frame ever carries the key, even from a controller that echoes it', async () => {
    const d = await startDsf();
    const s = await setup([duet('mk3', d)]);
    const got: Array<string | Buffer> = [];
    for (const p of [
      '/machine/connect',
      '/machine/model',
      '/machine/echo',
      '/machine/noop',
      '/machine/disconnect',
    ]) {
      // (`/machine/echo` is no DSF request: supervisors only.)
      const r = await send(s, 'GET', `/machines/mk3${p}`, s.supervisor);
      expect(`${r.status} ${r.text}`, p).toMatch(/^2/);
      got.push(r.head, r.body);
    }
    const code = await send(s, 'POST', '/machines/mk3/machine/code', s.operator, { body: 'M25' });
    expect(code.status).toBe(200);
    got.push(code.head, code.body);
    const ws = await openWs(`ws://${s.gw.host}/machines/mk3/machine`, {
      Cookie: s.operator,
      Origin: s.gw.url,
    });
    got.push(ws.first);
    ws.ws.send('OK\n');
    got.push(await ws.next());
    await ws.close();
    expectNoKey(d.keys, ...got);
    // … nor the audit log.
    expectNoKey(d.keys, JSON.stringify(s.gw.gw.audit.all()));
  });

  it('a browser-supplied X-Session-Key or sessionKey is dropped; the controller gets the gateway’s key', async () => {
    const d = await startDsf();
    const s = await setup([duet('mk3', d)]);
    const r = await send(s, 'GET', '/machines/mk3/machine/model?sessionKey=browser-key', s.viewer, {
      headers: { 'X-Session-Key': 'browser-key' },
    });
    expect(r.status).toBe(200);
    const reqs = d.seen.filter((x) => pathOf(x.url) === '/machine/model');
    expect(reqs).toHaveLength(1);
    expect(reqs[0]?.headers['x-session-key']).toBe(d.keys[0]);
    expect(reqs[0]?.url).toBe('/machine/model');
    expect(JSON.stringify(d.seen)).not.toContain('browser-key');
    // The socket too: the upstream URL carries the gateway's key, not the browser's.
    const ws = await openWs(`ws://${s.gw.host}/machines/mk3/machine?sessionKey=browser-key`, {
      Cookie: s.viewer,
      Origin: s.gw.url,
      'X-Session-Key': 'browser-key',
    });
    await ws.close();
    expect(d.wsSeen).toHaveLength(1);
    const up = new URL(d.wsSeen[0]?.url ?? '', 'http://dsf');
    expect(up.pathname).toBe('/machine');
    expect(up.searchParams.getAll('sessionKey')).toEqual([d.keys[0]]);
    expect(d.wsSeen[0]?.headers['x-session-key']).toBeUndefined();
  });

  it('every request reaching the controller carries the gateway’s key; two browsers share ONE session', async () => {
    const d = await startDsf();
    const s = await setup([duet('mk3', d)]);
    // Two browsers connect and read at the same time.
    const all = await Promise.all([
      send(s, 'GET', '/machines/mk3/machine/connect', s.viewer),
      send(s, 'GET', '/machines/mk3/machine/connect', s.operator),
      send(s, 'GET', '/machines/mk3/machine/model', s.viewer),
      send(s, 'GET', '/machines/mk3/machine/model', s.operator),
    ]);
    expect(all.map((a) => a.status)).toEqual([200, 200, 200, 200]);
    await send(s, 'POST', '/machines/mk3/machine/code', s.operator, { body: 'M25' });
    expect(count(d, '/machine/connect')).toBe(1);
    expect(d.keys).toHaveLength(1);
    for (const x of d.seen.filter((y) => pathOf(y.url) !== '/machine/connect'))
      expect(x.headers['x-session-key'], `${x.method} ${x.url}`).toBe(d.keys[0]);
    // The browser's disconnect does not end the shared session.
    const bye = await send(s, 'GET', '/machines/mk3/machine/disconnect', s.viewer);
    expect(bye.status).toBe(204);
    expect(count(d, '/machine/disconnect')).toBe(0);
    expect((await send(s, 'GET', '/machines/mk3/machine/model', s.operator)).status).toBe(200);
    expect(count(d, '/machine/connect')).toBe(1);
  });

  it('an expired key is renewed: a read is retried once, a command is never sent twice', async () => {
    const d = await startDsf();
    const s = await setup([duet('mk3', d)]);
    expect((await send(s, 'GET', '/machines/mk3/machine/model', s.viewer)).status).toBe(200);
    expect(d.keys).toHaveLength(1);

    d.expire();
    // (A query makes it a read the gateway does not share: it must reach the controller.)
    const read = await send(s, 'GET', '/machines/mk3/machine/model?again=1', s.viewer);
    expect(read.status).toBe(200);
    expect(d.keys).toHaveLength(2);
    const models = d.seen.filter((x) => pathOf(x.url) === '/machine/model');
    expect(models.map((x) => x.headers['x-session-key'])).toEqual([d.keys[0], d.keys[0], d.keys[1]]);

    d.expire();
    const cmd = await send(s, 'POST', '/machines/mk3/machine/code', s.operator, { body: 'M25' });
    expect(cmd.status).toBe(403);
    expect(d.seen.filter((x) => x.method === 'POST')).toHaveLength(1);
    // The key was renewed for next time: the next command goes through on the first try.
    await until(() => d.keys.length === 3);
    const again = await send(s, 'POST', '/machines/mk3/machine/code', s.operator, { body: 'M25' });
    expect(again.status).toBe(200);
    const posts = d.seen.filter((x) => x.method === 'POST');
    expect(posts.map((x) => x.headers['x-session-key'])).toEqual([d.keys[1], d.keys[2]]);
    expect(count(d, '/machine/connect')).toBe(3);
    expectNoKey(d.keys, read.head, read.body, cmd.head, cmd.body, again.head, again.body);
  });

  it('the configured password opens the session; what the browser typed is not used', async () => {
    const d = await startDsf('machine-pass-9');
    const s = await setup([duet('mk3', d, { secrets: { password: 'machine-pass-9' } })]);
    const r = await send(s, 'GET', '/machines/mk3/machine/connect?password=typed-guess', s.viewer);
    expect(r.status).toBe(200);
    expect(d.seen[0]?.url).toBe('/machine/connect?password=machine-pass-9');
    expect(r.text).not.toContain('machine-pass-9');
    expectNoKey(d.keys, r.head, r.body);
  });

  it('a password typed into the login form: a wrong one gets DSF’s 403, a right one is kept (never echoed or logged)', async () => {
    const typed = 'typed-pass-4242';
    const d = await startDsf(typed);
    const s = await setup([duet('mk3', d)]);
    // No password: DSF's 403, so the console shows its login form.
    expect((await send(s, 'GET', '/machines/mk3/machine/connect', s.viewer)).status).toBe(403);
    expect((await send(s, 'GET', '/machines/mk3/machine/model', s.viewer)).status).toBe(403);
    const wrong = await send(s, 'GET', '/machines/mk3/machine/connect?password=nope-nope', s.viewer);
    expect(wrong.status).toBe(403);
    expect(wrong.text).toBe('Invalid password');
    const right = await send(s, 'GET', `/machines/mk3/machine/connect?password=${typed}`, s.viewer);
    expect(right.status).toBe(200);
    expect(JSON.parse(right.text)).not.toHaveProperty('sessionKey');
    const connects = count(d, '/machine/connect');
    // Kept by the gateway: another browser without the password uses the same session.
    const other = await send(s, 'GET', '/machines/mk3/machine/connect', s.operator);
    expect(other.status).toBe(200);
    expect((await send(s, 'GET', '/machines/mk3/machine/echo', s.supervisor)).text).not.toContain(typed);
    // … and renewed with it when the session expires.
    d.expire();
    expect((await send(s, 'GET', '/machines/mk3/machine/model', s.operator)).status).toBe(200);
    expect(count(d, '/machine/connect')).toBe(connects + 1);
    // A command that fails shows up in the audit log, without the password or the key.
    d.expire();
    await send(s, 'POST', `/machines/mk3/machine/code?x=${typed}`, s.supervisor, { body: 'M115' });
    const audit = JSON.stringify(s.gw.gw.audit.all());
    expect(audit).toContain('/machine/code');
    expect(audit).not.toContain(typed);
    expectNoKey(d.keys, audit, right.head, right.body, other.head, other.body);
  });

  it('keeps the session alive while browsers use the machine, then lets it go', async () => {
    const d = await startDsf();
    const s = await setup(
      [duet('mk3', d)],
      withHooks({ keepAlive: { path: '/machine/noop', everyMs: 40, whileUsedWithinMs: 400 } }),
    );
    expect((await send(s, 'GET', '/machines/mk3/machine/model', s.viewer)).status).toBe(200);
    await until(() => count(d, '/machine/noop') >= 3);
    for (const x of d.seen.filter((y) => pathOf(y.url) === '/machine/noop'))
      expect(x.headers['x-session-key']).toBe(d.keys[0]);
    // Unused: the gateway ends the session and stops the noops.
    await until(() => count(d, '/machine/disconnect') === 1, 3000);
    const noops = count(d, '/machine/noop');
    await new Promise((r) => setTimeout(r, 200));
    expect(count(d, '/machine/noop')).toBe(noops);
    expect(d.valid.size).toBe(0);
    // The next use opens a new one first: a command is not refused for a stale key.
    const cmd = await send(s, 'POST', '/machines/mk3/machine/code', s.operator, { body: 'M25' });
    expect(cmd.status).toBe(200);
    expect(d.keys).toHaveLength(2);
  });

  it('no noop while a socket holds the session open', async () => {
    const d = await startDsf();
    const s = await setup(
      [duet('mk3', d)],
      withHooks({ keepAlive: { path: '/machine/noop', everyMs: 30, whileUsedWithinMs: 150 } }, 100),
    );
    const ws = await openWs(`ws://${s.gw.host}/machines/mk3/machine`, { Cookie: s.viewer, Origin: s.gw.url });
    await new Promise((r) => setTimeout(r, 400));
    expect(count(d, '/machine/noop')).toBe(0);
    expect(count(d, '/machine/disconnect')).toBe(0);
    await ws.close();
    await until(() => count(d, '/machine/disconnect') === 1, 3000);
  });

  it('closing the gateway ends its held sessions', async () => {
    const d = await startDsf();
    const s = await setup([duet('mk3', d)]);
    expect((await send(s, 'GET', '/machines/mk3/machine/model', s.viewer)).status).toBe(200);
    s.gw.gw.close();
    await until(() => count(d, '/machine/disconnect') === 1, 3000);
    expect(d.seen.at(-1)?.headers['x-session-key']).toBe(d.keys[0]);
  });
});

describe('held Duet session on a simulated machine', () => {
  function passwordSim(password: string): Families {
    return {
      duet: { ...duetFamily, createSimulator: (o) => new DuetSimulator({ ...o, password }) },
    };
  }

  it('the browser gets no key; the simulator (with a password) gets the gateway’s', async () => {
    const s = await setup(
      [duet('sim', null, { secrets: { password: 'sim-pass-77' } })],
      passwordSim('sim-pass-77'),
    );
    const c = await send(s, 'GET', '/machines/sim/machine/connect', s.viewer);
    expect(c.status).toBe(200);
    expect(JSON.parse(c.text)).not.toHaveProperty('sessionKey');
    const model = await send(s, 'GET', '/machines/sim/machine/model', s.viewer);
    expect(model.status).toBe(200);
    expect(JSON.parse(model.text)).toHaveProperty('state');
    // The socket: the simulator takes it only with a valid key.
    const ws = await openWs(`ws://${s.gw.host}/machines/sim/machine`, { Cookie: s.viewer, Origin: s.gw.url });
    expect(JSON.parse(ws.first)).toHaveProperty('sbc');
    await ws.close();
    const code = await send(s, 'POST', '/machines/sim/machine/code', s.operator, { body: 'M25' });
    expect(code.status).toBe(200);
    expect(c.text + model.text + ws.first + code.text).not.toMatch(/sim-\d+-/);
  });

  it('without a configured password the login form works against the simulator', async () => {
    const s = await setup([duet('sim', null)], passwordSim('sim-pass-78'));
    expect((await send(s, 'GET', '/machines/sim/machine/connect', s.viewer)).status).toBe(403);
    expect((await send(s, 'GET', '/machines/sim/machine/connect?password=wrong-one', s.viewer)).status).toBe(
      403,
    );
    const ok = await send(s, 'GET', '/machines/sim/machine/connect?password=sim-pass-78', s.viewer);
    expect(ok.status).toBe(200);
    expect(ok.text).not.toMatch(/sim-\d+-/);
    expect((await send(s, 'GET', '/machines/sim/machine/model', s.operator)).status).toBe(200);
  });
});

void WebSocket;
