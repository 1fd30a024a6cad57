import { afterEach, describe, expect, it } from 'vitest';
import { WebSocket } from 'ws';
import type { AuditEntry } from './audit';
import { READ_SOCKET_LIMITS } from './read-socket';
import {
  consoleFetch,
  login,
  openWs,
  user,
  type Running,
  type Stub,
  stubFor,
  gatewayFor,
  stubEntry,
} from './test-util';

/**
 * The page's read socket (read-socket.ts) is a second way to read a machine: every attack the
 * HTTP path is tested against is tried here too, through the real gateway and a stub controller.
 */

const cleanups: Array<() => Promise<void> | void> = [];
afterEach(async () => {
  for (const c of cleanups.splice(0).reverse()) await c();
});

const SECRET = 'k3y-that-must-never-leave-9731';

interface Setup {
  gw: Running;
  stub: Stub;
  audit(): AuditEntry[];
}

async function setup(): Promise<Setup> {
  const stub = await stubFor(cleanups);
  const machine = (id: string) => stubEntry(id, stub.url, { secrets: { apiKey: SECRET } });
  const gw = await gatewayFor(cleanups, [machine('p1'), machine('p2')], {
    users: [
      user('vera', 'viewer', 'viewer-pass-1'),
      user('otto', 'operator', 'operator-pass-1'),
      user('lena', 'operator', 'limited-pass-1', { machines: ['p2'] }),
    ],
  });
  const audit = (): AuditEntry[] => gw.gw.audit.all();
  return { gw, stub, audit };
}

interface Reader {
  ws: WebSocket;
  ask(msg: unknown): Promise<Record<string, unknown>>;
  closed: Promise<{ code: number; reason: string }>;
}

async function reader(s: Setup, cookie: string): Promise<Reader> {
  const w = await openWs(`ws://${s.gw.host}/api/reads`, cookie ? { Cookie: cookie } : {}, false);
  cleanups.push(() => w.close());
  const closed = new Promise<{ code: number; reason: string }>((r) =>
    w.ws.once('close', (code, reason) => r({ code, reason: String(reason) })),
  );
  return {
    ws: w.ws,
    closed,
    async ask(msg) {
      w.ws.send(typeof msg === 'string' ? msg : JSON.stringify(msg));
      return JSON.parse(await w.next()) as Record<string, unknown>;
    },
  };
}

async function refusedUpgrade(s: Setup, headers: Record<string, string>): Promise<number> {
  return new Promise((resolve, reject) => {
    const ws = new WebSocket(`ws://${s.gw.host}/api/reads`, { headers });
    ws.once('unexpected-response', (_req, res) => {
      ws.terminate();
      resolve(res.statusCode ?? 0);
    });
    ws.once('open', () => {
      ws.terminate();
      reject(new Error('the upgrade was accepted'));
    });
    ws.once('error', () => undefined);
  });
}

describe('the read socket answers reads exactly as HTTP does', () => {
  it('same status and body as the GET over HTTP; the controller sees the gateway, not the browser', async () => {
    const s = await setup();
    const cookie = await login(s.gw.url, 'vera', 'viewer-pass-1');
    const http = await consoleFetch(`${s.gw.url}/machines/p1/status?x=1`, { headers: { Cookie: cookie } });
    const httpBody = (await http.json()) as unknown;
    const r = await reader(s, cookie);
    const a = await r.ask({ id: 7, url: '/machines/p1/status?x=1', headers: { 'X-Shopdeck': '1' } });
    expect(a.id).toBe(7);
    expect(a.status).toBe(http.status);
    expect(JSON.parse(String(a.body))).toEqual(httpBody);
    const seen = s.stub.seen.at(-1);
    expect(seen?.url).toBe('/status?x=1');
    expect(seen?.headers.cookie).toBeUndefined();
    expect(seen?.headers['x-shopdeck']).toBeUndefined();
    // The family's secret was added upstream, as for HTTP.
    expect(seen?.headers['x-api-key']).toBe(SECRET);
  });

  it('a secret the controller echoes is scrubbed from the socket answer as from the HTTP one', async () => {
    const s = await setup();
    s.stub.respond = (req, res) => {
      res.writeHead(200, { 'Content-Type': 'application/json' });
      res.end(JSON.stringify({ echoed: req.headers['x-api-key'] }));
    };
    const cookie = await login(s.gw.url, 'vera', 'viewer-pass-1');
    const r = await reader(s, cookie);
    const a = await r.ask({ id: 1, url: '/machines/p1/status' });
    expect(a.status).toBe(200);
    expect(String(a.body)).not.toContain(SECRET);
    expect(JSON.stringify(a)).not.toContain(SECRET);
  });

  it('only the answer headers the console reads are passed (no Set-Cookie)', async () => {
    const s = await setup();
    const cookie = await login(s.gw.url, 'vera', 'viewer-pass-1');
    const r = await reader(s, cookie);
    const a = await r.ask({ id: 1, url: '/machines/p1/status' });
    expect(Object.keys(a.headers as object).sort()).toEqual(['content-type']);
  });
});

describe('attacks on the read socket', () => {
  it('another site cannot open it with the user’s cookie (Origin checked; refusal audited)', async () => {
    const s = await setup();
    const cookie = await login(s.gw.url, 'otto', 'operator-pass-1');
    expect(await refusedUpgrade(s, { Cookie: cookie, Origin: 'http://evil.example' })).toBe(403);
    expect(await refusedUpgrade(s, { Cookie: cookie })).toBe(403); // no Origin at all
    expect(await refusedUpgrade(s, { Cookie: cookie, Origin: 'null' })).toBe(403);
    const refused = s.audit().filter((e) => e.type === 'refused' && e.path === '/api/reads');
    expect(refused.length).toBe(3);
    expect(refused[0]?.user).toBe('otto');
  });

  it('no login: the upgrade is refused (401)', async () => {
    const s = await setup();
    expect(await refusedUpgrade(s, { Origin: s.gw.url })).toBe(401);
  });

  it('a machine the user may not use: the same refusal as HTTP, nothing reaches it', async () => {
    const s = await setup();
    const cookie = await login(s.gw.url, 'lena', 'limited-pass-1');
    const http = await consoleFetch(`${s.gw.url}/machines/p1/status`, { headers: { Cookie: cookie } });
    const before = s.stub.seen.length;
    const r = await reader(s, cookie);
    const a = await r.ask({ id: 1, url: '/machines/p1/status' });
    expect(a.status).toBe(http.status);
    expect(a.status).toBeGreaterThanOrEqual(403);
    // The gateway's own refusal, marked as over HTTP: the page never reads it as the controller's.
    expect((a.headers as Record<string, string>)['x-shopdeck-gateway']).toBe('error');
    expect(http.headers.get('x-shopdeck-gateway')).toBe('error');
    expect(s.stub.seen.length).toBe(before);
    expect((await r.ask({ id: 2, url: '/machines/p2/status' })).status).toBe(200);
  });

  it('a command is never performed over the socket: the page is told to use HTTP, the controller sees nothing', async () => {
    const s = await setup();
    const cookie = await login(s.gw.url, 'otto', 'operator-pass-1');
    const r = await reader(s, cookie);
    const before = s.stub.seen.length;
    const a = await r.ask({ id: 1, url: '/machines/p1/job?action=pause' });
    expect(a).toEqual({ id: 1, fallback: expect.stringMatching(/command/) as unknown });
    expect(s.stub.seen.length).toBe(before);
    expect(s.audit().filter((e) => e.type === 'command')).toEqual([]);
  });

  it('only /machines/<id>/… is read; an unknown machine is 404', async () => {
    const s = await setup();
    const cookie = await login(s.gw.url, 'vera', 'viewer-pass-1');
    const r = await reader(s, cookie);
    expect((await r.ask({ id: 1, url: '/api/audit' })).status).toBe(400);
    expect((await r.ask({ id: 2, url: 'http://127.0.0.1:1/machines/p1/status' })).status).toBe(400);
    const a = await r.ask({ id: 3, url: '/machines/nope/status' });
    expect(a.status).toBe(404);
    expect((a.headers as Record<string, string>)['x-shopdeck-gateway']).toBe('error');
    expect(s.stub.seen.length).toBe(0);
  });

  it('a malformed message (a header that smuggles a line break), a binary one or an oversized one closes the socket', async () => {
    const s = await setup();
    const cookie = await login(s.gw.url, 'vera', 'viewer-pass-1');
    const a = await reader(s, cookie);
    a.ws.send('{"id": "1", "url": "/machines/p1/status"}');
    expect((await a.closed).code).toBe(1008);
    const b = await reader(s, cookie);
    b.ws.send(JSON.stringify({ id: 1, url: '/machines/p1/status', method: 'POST' })); // extra field
    expect((await b.closed).code).toBe(1008);
    const c = await reader(s, cookie);
    c.ws.send(Buffer.from('{}'), { binary: true });
    expect((await c.closed).code).toBe(1003);
    const e = await reader(s, cookie);
    e.ws.send(
      JSON.stringify({ id: 1, url: '/machines/p1/status', headers: { 'X-A': 'v\r\nX-Api-Key: forged' } }),
    );
    expect((await e.closed).code).toBe(1008);
    const f = await reader(s, cookie);
    f.ws.send(JSON.stringify({ id: 1, url: '/machines/p1/status', headers: { 'Bad Name': 'v' } }));
    expect((await f.closed).code).toBe(1008);
    const d = await reader(s, cookie);
    d.ws.send(JSON.stringify({ id: 1, url: `/machines/p1/${'a'.repeat(READ_SOCKET_LIMITS.maxMessage)}` }));
    expect((await d.closed).code).toBe(1009);
    expect(s.stub.seen.length).toBe(0);
  });

  it('after logout the next read is refused (401) and the socket closes', async () => {
    const s = await setup();
    const cookie = await login(s.gw.url, 'vera', 'viewer-pass-1');
    const r = await reader(s, cookie);
    expect((await r.ask({ id: 1, url: '/machines/p1/status' })).status).toBe(200);
    await consoleFetch(`${s.gw.url}/api/logout`, { method: 'POST', headers: { Cookie: cookie } });
    const before = s.stub.seen.length;
    expect((await r.ask({ id: 2, url: '/machines/p1/status' })).status).toBe(401);
    expect((await r.closed).code).toBe(4401);
    expect(s.stub.seen.length).toBe(before);
  });

  it('a controller that refuses its key (401) answers 401 for its own read; the socket stays open for the others', async () => {
    const s = await setup();
    const cookie = await login(s.gw.url, 'vera', 'viewer-pass-1');
    const r = await reader(s, cookie);
    s.stub.respond = (req, res) => {
      // A TouchCut refusing its API key, a Duet whose session expired.
      res.writeHead(401, { 'Content-Type': 'application/json' });
      res.end(JSON.stringify({ error: 'invalid api key' }));
    };
    const refused = await r.ask({ id: 1, url: '/machines/p1/status' });
    expect(refused.status).toBe(401);
    s.stub.respond = (req, res) => {
      res.writeHead(200, { 'Content-Type': 'application/json' });
      res.end(JSON.stringify({ ok: true, path: req.url }));
    };
    const other = await r.ask({ id: 2, url: '/machines/p2/status' });
    expect(other.status).toBe(200);
    expect(r.ws.readyState).toBe(WebSocket.OPEN);
  });

  it('a page cannot make the gateway hold more than its share of reads at once', async () => {
    const s = await setup();
    const held: Array<() => void> = [];
    s.stub.respond = (_req, res) => {
      held.push(() => {
        res.writeHead(200, { 'Content-Type': 'application/json' });
        res.end('{}');
      });
    };
    const cookie = await login(s.gw.url, 'vera', 'viewer-pass-1');
    const w = await openWs(`ws://${s.gw.host}/api/reads`, { Cookie: cookie }, false);
    cleanups.push(() => w.close());
    const n = READ_SOCKET_LIMITS.maxInFlight + 5;
    for (let id = 1; id <= n; id++) w.ws.send(JSON.stringify({ id, url: `/machines/p1/status?n=${id}` }));
    const early: Array<Record<string, unknown>> = [];
    for (let i = 0; i < 5; i++) early.push(JSON.parse(await w.next()) as Record<string, unknown>);
    expect(early.every((m) => typeof m.fallback === 'string')).toBe(true);
    expect(early.map((m) => m.id)).toEqual([n - 4, n - 3, n - 2, n - 1, n]);
    for (const h of held.splice(0)) h();
  });

  it('an endless answer is cut at the socket’s limit: not gathered further, the page told to read it over HTTP, the controller asked once', async () => {
    const s = await setup();
    s.stub.respond = (_req, res) => {
      res.writeHead(200, { 'Content-Type': 'application/json' });
      const chunk = Buffer.alloc(1024 * 1024, 0x20);
      let sent = 0;
      const more = (): void => {
        while (sent < READ_SOCKET_LIMITS.maxAnswer + 2 * chunk.length) {
          sent += chunk.length;
          if (!res.write(chunk)) {
            res.once('drain', more);
            return;
          }
        }
        res.end('{}');
      };
      res.on('error', () => undefined);
      more();
    };
    const cookie = await login(s.gw.url, 'vera', 'viewer-pass-1');
    const r = await reader(s, cookie);
    const a = await r.ask({ id: 1, url: '/machines/p1/rr_reply' });
    // Where it streams with back-pressure instead of being held whole (a controller's reply
    // queue, RepRapFirmware's rr_reply, answers a few kB: only a file is this large).
    expect(a.status).toBeUndefined();
    expect(String(a.fallback)).toMatch(/larger than .* over HTTP/);
    expect(s.stub.seen.filter((q) => q.url === '/rr_reply').length).toBe(1);
  });
});
