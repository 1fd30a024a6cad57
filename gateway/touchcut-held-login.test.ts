import http, { type IncomingHttpHeaders, type IncomingMessage, type ServerResponse } from 'node:http';
import type { AddressInfo } from 'node:net';
import path from 'node:path';
import { afterEach, describe, expect, it } from 'vitest';
import { WebSocketServer } from 'ws';
import { touchcutFamily } from '../src/controllers/touchcut/family';
import type { MachineEntry } from './machines';
import { login, openWs, startGateway, tempDir, user, writeJson, type Running } from './test-util';

/**
 * The gateway holds the TouchCut user login (src/controllers/touchcut/gateway.ts on
 * held-session.ts): a console login is performed by the gateway, the JWT stays there (shared by
 * every viewer of the machine) and no byte a browser gets ever holds it; whatever credential a
 * browser sends is dropped. Real sockets: the real gateway on a plain server, and a TouchCut
 * stand-in that issues JWTs and enforces them (the manual's auth, change-password and 401).
 */

const cleanups: Array<() => Promise<void> | void> = [];
afterEach(async () => {
  for (const c of cleanups.splice(0).reverse()) await c();
});

const PW = 'console-pass-1';
const API_KEY = 'TC-API-KEY-0123456789abcdef';
const TC_PASSWORD = 'tc-Op-pass-8842';

interface Seen {
  method: string;
  url: string;
  headers: IncomingHttpHeaders;
  body: string;
}

interface TouchCut {
  url: string;
  seen: Seen[];
  wsSeen: IncomingHttpHeaders[];
  /** Every JWT it ever issued. */
  tokens: string[];
  valid: Set<string>;
  /** The user's password (a password change sets it). */
  password: string;
  /** Forget every JWT (they expired, or TouchCut restarted). */
  expire(): void;
}

const b64url = (s: string): string => Buffer.from(s).toString('base64url');
const pathOf = (url: string): string => url.split('?')[0] ?? url;
const count = (t: TouchCut, method: string, p: string): number =>
  t.seen.filter((s) => s.method === method && pathOf(s.url) === p).length;

/** A TouchCut stand-in: `POST rest/v1/auth` issues JWTs; reads want a valid JWT or the API key. */
async function startTouchcut(): Promise<TouchCut> {
  const t: TouchCut = {
    url: '',
    seen: [],
    wsSeen: [],
    tokens: [],
    valid: new Set(),
    password: TC_PASSWORD,
    expire: () => t.valid.clear(),
  };
  let n = 0;
  const issue = (): string => {
    const exp = Math.floor(Date.now() / 1000) + 900;
    const token = `${b64url('{"alg":"HS256","typ":"JWT"}')}.${b64url(JSON.stringify({ sub: 'operator', exp, n: ++n }))}.${b64url(`sig-${n}-${Math.random()}`)}`;
    t.tokens.push(token);
    t.valid.add(token);
    return token;
  };
  const json = (
    res: ServerResponse,
    status: number,
    body: unknown,
    extra: Record<string, string> = {},
  ): void => {
    res.writeHead(status, { 'Content-Type': 'application/json; charset=utf-8', ...extra });
    res.end(JSON.stringify(body));
  };
  const handler = (req: IncomingMessage, res: ServerResponse): void => {
    const chunks: Buffer[] = [];
    req.on('data', (c: Buffer) => chunks.push(c));
    req.on('end', () => {
      const body = Buffer.concat(chunks).toString('utf8');
      t.seen.push({ method: req.method ?? '', url: req.url ?? '', headers: req.headers, body });
      const p = pathOf(req.url ?? '/').toLowerCase();
      const bearer = /^Bearer\s+(\S+)$/i.exec(req.headers.authorization ?? '')?.[1];
      const jwtOk = bearer !== undefined && t.valid.has(bearer);
      const keyOk = req.headers['x-touchcut-api-key'] === API_KEY;
      if (p === '/rest/v1/auth' && req.method === 'POST') {
        const f = new URLSearchParams(body);
        if (!f.get('username'))
          return json(res, 400, { code: '1003', msg: 'Required parameter missing: username' });
        if (f.get('username') !== 'operator') return json(res, 400, { code: '101', msg: 'Invalid Username' });
        if (f.get('password') !== t.password) return json(res, 400, { code: '102', msg: 'Invalid Password' });
        // A careless controller: the token in a cookie too.
        const token = issue();
        return json(res, 200, { success: 'true', token }, { 'Set-Cookie': `__Secure-jwt=${token}; Secure` });
      }
      if (p === '/rest/v1/auth/change-password' && req.method === 'POST') {
        if (!jwtOk) {
          res.writeHead(401);
          res.end();
          return;
        }
        const f = new URLSearchParams(body);
        if (f.get('old-password') !== t.password)
          return json(res, 400, { code: '102', msg: 'Invalid Password' });
        t.password = f.get('new-password') ?? '';
        return json(res, 200, { success: 'true', token: issue() });
      }
      if (!jwtOk && !keyOk) {
        res.writeHead(401);
        res.end();
        return;
      }
      if (p === '/rest/v1/status')
        return json(res, 200, { machineState: 'Idle', currentUser: jwtOk ? 'operator' : null });
      // Undocumented (supervisor only): a hostile controller echoing what it got, token included.
      if (p === '/rest/v1/echo')
        return json(res, 200, { headers: req.headers, body }, { 'X-Echo': req.headers.authorization ?? '' });
      json(res, 404, { code: '404', msg: 'Not Found' });
    });
  };
  const server = http.createServer(handler);
  const wss = new WebSocketServer({ server });
  wss.on('connection', (sock, req) => {
    t.wsSeen.push(req.headers);
    sock.send(JSON.stringify({ upgrade: req.headers }));
    sock.on('message', (m) => sock.send(`echo:${String(m)} ${req.headers.authorization ?? ''}`));
  });
  await new Promise<void>((r) => server.listen(0, '127.0.0.1', () => r()));
  t.url = `http://127.0.0.1:${(server.address() as AddressInfo).port}`;
  cleanups.push(async () => {
    for (const c of wss.clients) c.terminate();
    await new Promise<void>((r) => wss.close(() => r()));
    server.closeAllConnections();
    await new Promise<void>((r) => server.close(() => r()));
  });
  return t;
}

interface Setup {
  gw: Running;
  dir: string;
  viewer: string;
  operator: string;
  supervisor: string;
}

async function setup(machines: MachineEntry[]): Promise<Setup> {
  const t = tempDir();
  cleanups.push(t.cleanup);
  const usersFile = writeJson(path.join(t.dir, 'users.json'), {
    users: [user('vic', 'viewer', PW), user('ola', 'operator', PW), user('sue', 'supervisor', PW)],
  });
  const gw = await startGateway({
    machines: { file: null, machines },
    families: { touchcut: touchcutFamily },
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

function plasma(tc: TouchCut | null, extra: Partial<MachineEntry> = {}): MachineEntry {
  return {
    id: 'plasma',
    name: 'Plasma',
    kind: 'touchcut',
    simulated: tc === null,
    url: tc ? new URL(tc.url) : null,
    wsUrl: null,
    secrets: {},
    ...extra,
  };
}

interface Answer {
  status: number;
  /** Every header line as sent. */
  head: string;
  text: string;
}

/** A request as the console's page sends it (`X-Shopdeck: 1`), with the raw answer. */
function send(
  s: Setup,
  method: string,
  p: string,
  cookie: string,
  opts: { headers?: Record<string, string>; body?: string; console?: boolean } = {},
): Promise<Answer> {
  const u = new URL(s.gw.url);
  return new Promise((resolve, reject) => {
    const req = http.request(
      {
        host: u.hostname,
        port: u.port,
        method,
        path: `/machines/plasma${p}`,
        headers: {
          Cookie: cookie,
          ...(opts.console === false ? {} : { 'X-Shopdeck': '1' }),
          ...opts.headers,
        },
      },
      (res) => {
        const chunks: Buffer[] = [];
        res.on('data', (c: Buffer) => chunks.push(c));
        res.on('end', () =>
          resolve({
            status: res.statusCode ?? 0,
            head: res.rawHeaders.join('\n'),
            text: Buffer.concat(chunks).toString('utf8'),
          }),
        );
      },
    );
    req.on('error', reject);
    req.end(opts.body);
  });
}

const FORM = { 'Content-Type': 'application/x-www-form-urlencoded' };

let probes = 0;
/**
 * A status read no other read shares (the gateway answers identical reads within a second once,
 * upstream-http.ts; a parameter the console never sends makes it a read of its own).
 */
const status = (): string => `/rest/v1/status?probe=${++probes}`;

/** The console's login form, sent by `cookie`'s browser. */
function tcLogin(s: Setup, cookie: string, password = TC_PASSWORD): Promise<Answer> {
  return send(s, 'POST', '/rest/v1/auth', cookie, {
    headers: FORM,
    body: new URLSearchParams({ username: 'operator', password }).toString(),
  });
}

/** No byte the browser got holds any JWT the controller issued (raw, URL-encoded, base64, its parts). */
function expectNoToken(tokens: readonly string[], ...got: string[]): void {
  expect(tokens.length).toBeGreaterThan(0);
  for (const g of got) {
    for (const k of tokens) {
      const signature = k.split('.')[2] ?? k;
      for (const form of [k, encodeURIComponent(k), Buffer.from(k).toString('base64'), signature]) {
        expect(g.includes(form), `the browser got a JWT (${form.slice(0, 24)}…)`).toBe(false);
      }
    }
  }
}

async function audit(s: Setup): Promise<string> {
  await s.gw.gw.audit.flush();
  return JSON.stringify(s.gw.gw.audit.all());
}

describe('held TouchCut login: the JWT stays in the gateway', () => {
  it('after a console login no answer, header, cookie or WebSocket frame to any browser holds the JWT', async () => {
    const tc = await startTouchcut();
    const s = await setup([plasma(tc, { secrets: { apiKey: API_KEY } })]);
    const got: string[] = [];
    const l = await tcLogin(s, s.operator);
    expect(l.status).toBe(200);
    expect(JSON.parse(l.text)).toMatchObject({ success: 'true', loggedIn: true, user: 'operator' });
    expect((JSON.parse(l.text) as { expiresAt: number }).expiresAt).toBeGreaterThan(Date.now());
    expect(JSON.parse(l.text)).not.toHaveProperty('token');
    expect(l.head).not.toMatch(/set-cookie/i);
    got.push(l.head, l.text);
    for (const [cookie, p] of [
      [s.viewer, '/rest/v1/auth'],
      [s.viewer, status()],
      [s.operator, status()],
      [s.supervisor, '/rest/v1/echo'],
    ] as const) {
      const r = await send(s, 'GET', p, cookie);
      expect(r.status, p).toBe(200);
      got.push(r.head, r.text);
    }
    // The echo shows the controller got the JWT, redacted on the way back.
    expect(got.join('\n')).toContain('[redacted]');
    const cp = await send(s, 'POST', '/rest/v1/auth/change-password', s.operator, {
      headers: FORM,
      body: 'old-password=tc-Op-pass-8842&new-password=tc-New-pass-1&confirm-password=tc-New-pass-1',
    });
    expect(cp.status).toBe(200);
    got.push(cp.head, cp.text);
    // A socket: TouchCut has none, so even a supervisor's is refused before it reaches TouchCut
    // (issue 31), and the refusal holds no token either.
    const refused = await openWs(`ws://${s.gw.host}/machines/plasma/rest/v1/status`, {
      Cookie: s.supervisor,
    }).catch((e: { status?: number; body?: string }) => e);
    expect('status' in refused ? refused.status : 101).toBe(404);
    got.push('body' in refused ? String(refused.body) : '');
    expect(tc.wsSeen).toHaveLength(0);
    expect(tc.tokens).toHaveLength(2);
    expectNoToken(tc.tokens, ...got, await audit(s));
  });

  it('a browser’s own Authorization, __Secure-jwt cookie or X-TouchCut-API-Key never reaches TouchCut', async () => {
    const tc = await startTouchcut();
    const s = await setup([plasma(tc, { secrets: { apiKey: API_KEY } })]);
    const forged = {
      Authorization: 'Bearer forged.jwt.value',
      'X-TouchCut-API-Key': 'forged-api-key',
    };
    const withCookie = (c: string): string => `${c}; __Secure-jwt=forged.cookie.jwt`;
    // No login: the gateway's API key, nothing of the browser's.
    const a = await send(s, 'GET', status(), withCookie(s.viewer), { headers: forged });
    expect(a.status).toBe(200);
    expect(JSON.parse(a.text)).toMatchObject({ currentUser: null });
    await tcLogin(s, s.operator);
    // With the login: the gateway's JWT, nothing of the browser's.
    const b = await send(s, 'GET', status(), withCookie(s.viewer), { headers: forged });
    expect(JSON.parse(b.text)).toMatchObject({ currentUser: 'operator' });
    await send(s, 'POST', '/rest/v1/auth/change-password', withCookie(s.operator), {
      headers: { ...FORM, ...forged },
      body: 'old-password=x&new-password=y&confirm-password=y',
    });
    await send(s, 'GET', '/rest/v1/echo', withCookie(s.supervisor), { headers: forged });
    // TouchCut has no socket: refused before anything reaches it (issue 31).
    await expect(
      openWs(`ws://${s.gw.host}/machines/plasma/rest/v1/status`, {
        Cookie: withCookie(s.supervisor),
        ...forged,
      }),
    ).rejects.toMatchObject({ status: 404 });
    expect(JSON.stringify([tc.seen, tc.wsSeen])).not.toMatch(/forged/);
    const reads = tc.seen.filter((x) => pathOf(x.url) !== '/rest/v1/auth');
    expect(reads.map((x) => x.headers.authorization ?? x.headers['x-touchcut-api-key'])).toEqual([
      API_KEY,
      `Bearer ${tc.tokens[0]}`,
      `Bearer ${tc.tokens[0]}`,
      `Bearer ${tc.tokens[0]}`,
    ]);
    for (const x of tc.seen) expect(x.headers.cookie, x.url).toBeUndefined();
    expect(tc.wsSeen).toHaveLength(0);
  });

  it('a viewer can neither log the machine in nor out; a login is an audited command without its password', async () => {
    const tc = await startTouchcut();
    const s = await setup([plasma(tc)]);
    const refused = await tcLogin(s, s.viewer);
    expect(refused.status).toBe(403);
    expect(JSON.parse(refused.text)).toMatchObject({ needs: 'operator' });
    expect(count(tc, 'POST', '/rest/v1/auth')).toBe(0);
    // A login from another site (no proof that the console sent it) is refused too.
    const crossSite = await send(s, 'POST', '/rest/v1/auth', s.operator, {
      headers: FORM,
      body: `username=operator&password=${TC_PASSWORD}`,
      console: false,
    });
    expect(crossSite.status).toBe(403);
    expect(count(tc, 'POST', '/rest/v1/auth')).toBe(0);
    // A wrong password: TouchCut's answer as it is, audited as a failed command.
    const wrong = await tcLogin(s, s.operator, 'tc-wrong-guess-1');
    expect(wrong.status).toBe(400);
    expect(JSON.parse(wrong.text)).toEqual({ code: '102', msg: 'Invalid Password' });
    expect((await tcLogin(s, s.operator)).status).toBe(200);
    const out = await send(s, 'DELETE', '/rest/v1/auth', s.viewer);
    expect(out.status).toBe(403);
    // The login stands: the viewer still reads with it.
    const st = await send(s, 'GET', status(), s.viewer);
    expect(JSON.parse(st.text)).toMatchObject({ currentUser: 'operator' });
    const log = await audit(s);
    const entries = (JSON.parse(log) as Array<Record<string, unknown>>).filter(
      (e) => e.path === '/rest/v1/auth',
    );
    expect(entries.map((e) => [e.type, e.result, e.user, e.method, e.status])).toEqual([
      ['refused', 'refused', 'vic', 'POST', undefined],
      ['command', 'error', 'ola', 'POST', 400],
      ['command', 'ok', 'ola', 'POST', 200],
      ['refused', 'refused', 'vic', 'DELETE', undefined],
    ]);
    expect(log).not.toContain(TC_PASSWORD);
    expect(log).not.toContain('tc-wrong-guess-1');
    expectNoToken(tc.tokens, log);
  });

  it('two browsers share one login: one upstream login, both read with it, a logout ends it for both', async () => {
    const tc = await startTouchcut();
    const s = await setup([plasma(tc, { secrets: { apiKey: API_KEY } })]);
    const before = await send(s, 'GET', '/rest/v1/auth', s.viewer);
    expect(JSON.parse(before.text)).toEqual({ loggedIn: false, user: null, expiresAt: null });
    expect((await tcLogin(s, s.operator)).status).toBe(200);
    const [v, o, state] = await Promise.all([
      send(s, 'GET', status(), s.viewer),
      send(s, 'GET', status(), s.operator),
      send(s, 'GET', '/rest/v1/auth', s.viewer),
    ]);
    expect([v.status, o.status, state.status]).toEqual([200, 200, 200]);
    expect(JSON.parse(v.text)).toMatchObject({ currentUser: 'operator' });
    expect(JSON.parse(state.text)).toMatchObject({ loggedIn: true, user: 'operator' });
    expect(count(tc, 'POST', '/rest/v1/auth')).toBe(1);
    expect(count(tc, 'GET', '/rest/v1/auth')).toBe(0);
    // Logout is answered by the gateway (TouchCut has none): the next reads use the API key.
    const bye = await send(s, 'DELETE', '/rest/v1/auth', s.operator);
    expect(bye.status).toBe(204);
    expect(tc.seen.filter((x) => x.method === 'DELETE')).toHaveLength(0);
    const after = await send(s, 'GET', status(), s.viewer);
    expect(JSON.parse(after.text)).toMatchObject({ currentUser: null });
    expect(tc.seen.at(-1)?.headers.authorization).toBeUndefined();
    expect(tc.seen.at(-1)?.headers['x-touchcut-api-key']).toBe(API_KEY);
    expect(JSON.parse((await send(s, 'GET', '/rest/v1/auth', s.operator)).text)).toMatchObject({
      loggedIn: false,
    });
  });

  it('an expired JWT: the browser gets the 401 (needs login), the gateway forgets it and never logs in again by itself', async () => {
    const tc = await startTouchcut();
    const s = await setup([plasma(tc)]);
    await tcLogin(s, s.operator);
    expect((await send(s, 'GET', status(), s.viewer)).status).toBe(200);
    tc.expire();
    const expired = await send(s, 'GET', status(), s.viewer);
    expect(expired.status).toBe(401);
    // Not sent again with a renewed login: the typed password was never kept.
    expect(count(tc, 'GET', '/rest/v1/status')).toBe(2);
    expect(count(tc, 'POST', '/rest/v1/auth')).toBe(1);
    const state = await send(s, 'GET', '/rest/v1/auth', s.viewer);
    expect(JSON.parse(state.text)).toEqual({ loggedIn: false, user: null, expiresAt: null });
    const next = await send(s, 'GET', status(), s.viewer);
    expect(next.status).toBe(401);
    expect(tc.seen.at(-1)?.headers.authorization).toBeUndefined();
    // A new login works at once.
    expect((await tcLogin(s, s.operator)).status).toBe(200);
    expect((await send(s, 'GET', status(), s.viewer)).status).toBe(200);
    expect(tc.seen.at(-1)?.headers.authorization).toBe(`Bearer ${tc.tokens[1]}`);
  });

  it('a password change is sent with the gateway’s JWT; the new one stays in the gateway', async () => {
    const tc = await startTouchcut();
    const s = await setup([plasma(tc)]);
    await tcLogin(s, s.operator);
    const cp = await send(s, 'POST', '/rest/v1/auth/change-password', s.operator, {
      headers: FORM,
      body: 'old-password=tc-Op-pass-8842&new-password=tc-New-pass-1&confirm-password=tc-New-pass-1',
    });
    expect(cp.status).toBe(200);
    const body = JSON.parse(cp.text) as Record<string, unknown>;
    expect(body).toMatchObject({ success: 'true', loggedIn: true, user: 'operator' });
    expect(body).not.toHaveProperty('token');
    expect(tc.tokens).toHaveLength(2);
    const sent = tc.seen.filter((x) => pathOf(x.url) === '/rest/v1/auth/change-password');
    expect(sent).toHaveLength(1);
    expect(sent[0]?.headers.authorization).toBe(`Bearer ${tc.tokens[0]}`);
    expect(sent[0]?.body).toContain('new-password=tc-New-pass-1');
    // The next request uses the new JWT.
    expect((await send(s, 'GET', status(), s.viewer)).status).toBe(200);
    expect(tc.seen.at(-1)?.headers.authorization).toBe(`Bearer ${tc.tokens[1]}`);
    // A viewer may not change it; a wrong old password is TouchCut's answer and keeps the JWT.
    const viewer = await send(s, 'POST', '/rest/v1/auth/change-password', s.viewer, {
      headers: FORM,
      body: 'old-password=a&new-password=b&confirm-password=b',
    });
    expect(viewer.status).toBe(403);
    const wrong = await send(s, 'POST', '/rest/v1/auth/change-password', s.operator, {
      headers: FORM,
      body: 'old-password=nope&new-password=b&confirm-password=b',
    });
    expect(wrong.status).toBe(400);
    expect(tc.seen.filter((x) => pathOf(x.url) === '/rest/v1/auth/change-password')).toHaveLength(2);
    expect((await send(s, 'GET', status(), s.viewer)).status).toBe(200);
    expect(tc.seen.at(-1)?.headers.authorization).toBe(`Bearer ${tc.tokens[1]}`);
    const log = await audit(s);
    expect(log).toContain('/rest/v1/auth/change-password');
    expect(log).not.toContain('tc-New-pass-1');
    expectNoToken(tc.tokens, cp.head, cp.text, wrong.text, log);
  });

  it('every other request under auth is answered 405 by the gateway and never reaches TouchCut', async () => {
    const tc = await startTouchcut();
    const s = await setup([plasma(tc)]);
    for (const [method, p] of [
      ['PUT', '/rest/v1/auth'],
      ['POST', '/rest/v1/auth/other'],
      ['POST', '/rest/v1/auth;x'],
      ['GET', '/rest/v1/auth/change-password'],
    ] as const) {
      const r = await send(s, method, p, s.supervisor, { headers: FORM, body: 'username=operator' });
      expect(r.status, `${method} ${p}`).toBe(405);
    }
    expect(tc.seen).toHaveLength(0);
  });
});

describe('held TouchCut login on a simulated machine', () => {
  it('the simulator’s login works through the gateway; the browser gets no JWT', async () => {
    const s = await setup([plasma(null)]);
    const l = await send(s, 'POST', '/rest/v1/auth', s.operator, {
      headers: FORM,
      body: 'username=operator&password=operator',
    });
    expect(l.status).toBe(200);
    expect(JSON.parse(l.text)).toMatchObject({ loggedIn: true, user: 'operator' });
    const st = await send(s, 'GET', status(), s.viewer);
    expect(st.status).toBe(200);
    expect(JSON.parse(st.text)).toHaveProperty('machineState');
    const all = l.head + l.text + st.head + st.text;
    // The simulator's JWTs end in a signature "simulated-signature-<n>" (base64url).
    expect(all).not.toContain(Buffer.from('simulated-signature-').toString('base64url').slice(0, 20));
    expect(all).not.toMatch(/"token"/);
    const bye = await send(s, 'DELETE', '/rest/v1/auth', s.operator);
    expect(bye.status).toBe(204);
  });
});
