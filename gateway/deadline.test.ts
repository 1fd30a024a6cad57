import http, { type IncomingMessage, type ServerResponse } from 'node:http';
import https from 'node:https';
import net, { type AddressInfo } from 'node:net';
import { Worker } from 'node:worker_threads';
import { afterEach, describe, expect, it } from 'vitest';
import type { AuditEntry } from './audit';
import { commandDeadlineMs, MAX_COMMAND_DEADLINE_MS } from './http-util';
import type { MachineEntry } from './machines';
import { consoleFetch, selfSignedCert, startGateway, tempDir, testFamily, type Running } from './test-util';

/**
 * Issue 15: commands have a deadline. The browser sends it (`X-Shopdeck-Deadline: <ms>`); the
 * gateway aborts its upstream request at that moment — also while it is still connecting or
 * pinning the controller's certificate — and answers 504 "not confirmed". A command never reaches
 * a machine after the browser was told it was not confirmed. Real sockets throughout: a controller
 * whose TCP accept queue is full (its connect completes only when it accepts again), one whose TLS
 * handshake is late, one that answers late.
 */

const cleanups: Array<() => Promise<void> | void> = [];
afterEach(async () => {
  for (const c of cleanups.splice(0).reverse()) await c();
});

const sleep = (ms: number): Promise<void> => new Promise((r) => setTimeout(r, ms));

function entry(id: string, url: string, extra: Partial<MachineEntry> = {}): MachineEntry {
  return {
    id,
    name: id === 'p1' ? 'Printer 1' : id,
    kind: 'prunt',
    simulated: false,
    url: new URL(url),
    wsUrl: null,
    secrets: {},
    ...extra,
  };
}

async function setup(m: MachineEntry, timeoutMs = 5000): Promise<Running> {
  const t = tempDir();
  cleanups.push(t.cleanup);
  const gw = await startGateway({
    machines: { file: null, machines: [m] },
    families: { prunt: testFamily('prunt') },
    dataDir: t.dir,
    env: {},
    timeoutMs,
  });
  cleanups.push(gw.close);
  return gw;
}

/** The operator's pause, as the console sends it: command id and deadline. */
function pause(gw: Running, deadlineMs: number | null, signal?: AbortSignal): Promise<Response> {
  const headers: Record<string, string> = { 'X-Shopdeck-Command': 'test.pause' };
  if (deadlineMs !== null) headers['X-Shopdeck-Deadline'] = String(deadlineMs);
  return consoleFetch(`${gw.url}/machines/p1/job?action=pause`, { headers, signal });
}

async function commandAudit(gw: Running): Promise<AuditEntry> {
  const until = Date.now() + 2000;
  for (;;) {
    const e = gw.gw.audit.all().find((a) => a.type === 'command');
    if (e) return e;
    if (Date.now() > until) throw new Error('no command in the audit log');
    await sleep(10);
  }
}

// ---------------------------------------------------------------- controllers

interface LateAccept {
  url: string;
  /** Request lines the controller read, with the time (ms since epoch) it read them. */
  lines: Array<{ line: string; at: number }>;
  close(): Promise<void>;
}

/**
 * A controller that accepts no TCP connection for `blockMs`: it listens with a backlog of one
 * and its thread is blocked, and two connections fill its accept queue, so the kernel drops the
 * gateway's SYN; the gateway's connect completes only after the controller accepts again (on a
 * SYN retransmission, about 1 s later). Then it reads and answers every request.
 */
async function lateAcceptController(blockMs: number): Promise<LateAccept> {
  const src = `
    const net = require('node:net');
    const { parentPort } = require('node:worker_threads');
    const srv = net.createServer((s) => {
      s.on('error', () => undefined);
      let buf = '';
      s.on('data', (d) => {
        buf += d.toString('latin1');
        const i = buf.indexOf('\\r\\n');
        if (i < 0) return;
        parentPort.postMessage({ line: buf.slice(0, i), at: Date.now() });
        buf = '';
        s.end('HTTP/1.1 200 OK\\r\\nContent-Type: application/json\\r\\nContent-Length: 11\\r\\nConnection: close\\r\\n\\r\\n{"ok":true}');
      });
    });
    srv.listen({ port: 0, host: '127.0.0.1', backlog: 1 }, () => {
      parentPort.postMessage({ port: srv.address().port });
      parentPort.once('message', (ms) => {
        Atomics.wait(new Int32Array(new SharedArrayBuffer(4)), 0, 0, ms);
        parentPort.postMessage({ awake: Date.now() });
      });
    });`;
  const worker = new Worker(src, { eval: true });
  const lines: LateAccept['lines'] = [];
  const port = await new Promise<number>((resolve) => {
    worker.on('message', (m: { port?: number; line?: string; at?: number }) => {
      if (m.port) resolve(m.port);
      if (m.line !== undefined && m.at !== undefined) lines.push({ line: m.line, at: m.at });
    });
  });
  worker.postMessage(blockMs);
  await sleep(50);
  // Fill the accept queue (backlog 1: two connections); both complete in the kernel.
  const fillers: net.Socket[] = [];
  for (let i = 0; i < 2; i++) {
    const s = net.connect(port, '127.0.0.1');
    s.on('error', () => undefined);
    fillers.push(s);
    await new Promise<void>((resolve, reject) => {
      s.once('connect', () => resolve());
      setTimeout(() => reject(new Error('a filler connection did not complete')), 500);
    });
  }
  const close = async (): Promise<void> => {
    for (const f of fillers) f.destroy();
    await worker.terminate();
  };
  cleanups.push(close);
  return { url: `http://127.0.0.1:${port}`, lines, close };
}

interface LateTls {
  url: string;
  lines: Array<{ line: string; at: number }>;
}

/** An HTTPS controller whose TLS handshake starts only `delayMs` after the TCP connection. */
async function lateTlsController(delayMs: number): Promise<LateTls> {
  const t = tempDir();
  cleanups.push(t.cleanup);
  const { key, cert } = selfSignedCert(t.dir, 'late');
  const lines: LateTls['lines'] = [];
  const tlsServer = https.createServer({ key, cert }, (req: IncomingMessage, res: ServerResponse) => {
    lines.push({ line: `${req.method ?? ''} ${req.url ?? ''}`, at: Date.now() });
    res.writeHead(200, { 'Content-Type': 'application/json' });
    res.end('{"ok":true}');
  });
  tlsServer.on('tlsClientError', () => undefined);
  const sockets = new Set<net.Socket>();
  const tcp = net.createServer({ pauseOnConnect: true }, (s) => {
    sockets.add(s);
    s.on('error', () => undefined);
    s.on('close', () => sockets.delete(s));
    setTimeout(() => {
      if (s.destroyed) return;
      tlsServer.emit('connection', s);
      s.resume();
    }, delayMs);
  });
  await new Promise<void>((r) => tcp.listen(0, '127.0.0.1', () => r()));
  cleanups.push(async () => {
    for (const s of sockets) s.destroy();
    await new Promise<void>((r) => tcp.close(() => r()));
  });
  return { url: `https://127.0.0.1:${(tcp.address() as AddressInfo).port}`, lines };
}

interface SlowController {
  url: string;
  seen: string[];
  /** Requests whose connection the gateway closed before the answer was written. */
  abandoned: string[];
}

/** Reads each request at once and answers it `answerMs` later. */
async function slowController(answerMs: number): Promise<SlowController> {
  const ctl: SlowController = { url: '', seen: [], abandoned: [] };
  const server = http.createServer((req, res) => {
    ctl.seen.push(req.url ?? '');
    res.on('close', () => {
      if (!res.writableFinished) ctl.abandoned.push(req.url ?? '');
    });
    req.resume();
    setTimeout(() => {
      if (res.destroyed) return;
      res.writeHead(200, { 'Content-Type': 'application/json' });
      res.end('{"ok":true}');
    }, answerMs);
  });
  await new Promise<void>((r) => server.listen(0, '127.0.0.1', () => r()));
  ctl.url = `http://127.0.0.1:${(server.address() as AddressInfo).port}`;
  cleanups.push(async () => {
    server.closeAllConnections();
    await new Promise<void>((r) => server.close(() => r()));
  });
  return ctl;
}

// ---------------------------------------------------------------- tests

const NOT_CONFIRMED =
  /^Printer 1 did not confirm pause the job within 0\.3 s: it may or may not have reached the machine$/;

describe('command deadlines (gateway)', () => {
  it('aborts a command still connecting at its deadline: 504 "not confirmed", and it never reaches the controller later', async () => {
    const ctl = await lateAcceptController(700);
    const gw = await setup(entry('p1', ctl.url));
    const t0 = Date.now();
    const r = await pause(gw, 300);
    const answeredAt = Date.now();
    expect(r.status).toBe(504);
    expect(answeredAt - t0).toBeGreaterThanOrEqual(280);
    expect(answeredAt - t0).toBeLessThan(900);
    expect(r.headers.get('x-shopdeck-gateway')).toBe('error');
    const body = (await r.json()) as { error: string; gateway: boolean; notConfirmed: boolean };
    expect(body).toMatchObject({ gateway: true, notConfirmed: true });
    expect(body.error).toMatch(NOT_CONFIRMED);
    // The controller accepts again at ~0.75 s; without the abort, the connect would complete on
    // the SYN retransmission (~1 s) and the pause would arrive then. Nothing arrives.
    await sleep(2200);
    expect(ctl.lines).toEqual([]);
    const audit = await commandAudit(gw);
    expect(audit).toMatchObject({ machine: 'p1', commandId: 'test.pause', result: 'error', status: 504 });
    expect(audit.error).toMatch(/^not confirmed within 0\.3 s/);
    expect(audit.error).toMatch(/not sent/);
  });

  it('aborts a command whose TLS handshake (certificate pinning) is not done by its deadline; it is never written', async () => {
    const ctl = await lateTlsController(700);
    const gw = await setup(entry('p1', ctl.url));
    const t0 = Date.now();
    const r = await pause(gw, 300);
    expect(r.status).toBe(504);
    expect(Date.now() - t0).toBeLessThan(900);
    expect(((await r.json()) as { error: string }).error).toMatch(NOT_CONFIRMED);
    await sleep(1500);
    expect(ctl.lines).toEqual([]);
    // The same controller with a deadline that leaves time for the handshake: delivered.
    const ok = await pause(gw, 3000);
    expect(ok.status).toBe(200);
    expect(ctl.lines.map((l) => l.line)).toEqual(['GET /job?action=pause']);
  });

  it('aborts a command the controller has read but not answered: 504 at the deadline, the upstream request closed', async () => {
    const ctl = await slowController(1500);
    const gw = await setup(entry('p1', ctl.url));
    const t0 = Date.now();
    const r = await pause(gw, 300);
    expect(r.status).toBe(504);
    expect(Date.now() - t0).toBeLessThan(900);
    expect(await r.json()).toEqual({
      error:
        'Printer 1 did not confirm pause the job within 0.3 s: it may or may not have reached the machine',
      gateway: true,
      notConfirmed: true,
    });
    expect(ctl.seen).toEqual(['/job?action=pause']);
    const until = Date.now() + 1000;
    while (ctl.abandoned.length === 0 && Date.now() < until) await sleep(10);
    expect(ctl.abandoned).toEqual(['/job?action=pause']);
    const audit = await commandAudit(gw);
    expect(audit.error).toMatch(/^not confirmed within 0\.3 s/);
    expect(audit.error).toMatch(/was sent/);
  });

  it('a deadline longer than the gateway’s idle timeout is the one that counts for a command', async () => {
    const ctl = await slowController(500);
    const gw = await setup(entry('p1', ctl.url), 200);
    const r = await pause(gw, 2000);
    expect(r.status).toBe(200);
    expect(await r.json()).toEqual({ ok: true });
    expect((await commandAudit(gw)).result).toBe('ok');
  });

  it('without a deadline header a command gets the gateway’s default deadline, and the same words', async () => {
    const ctl = await slowController(5000);
    const gw = await setup(entry('p1', ctl.url), 400);
    const r = await pause(gw, null);
    expect(r.status).toBe(504);
    const body = (await r.json()) as { error: string; notConfirmed: boolean };
    expect(body.notConfirmed).toBe(true);
    expect(body.error).toMatch(/^Printer 1 did not confirm pause the job within 0\.4 s: it may or may not/);
  });

  it('a command the browser gave up on before the connection was made is never sent', async () => {
    const ctl = await lateAcceptController(700);
    const gw = await setup(entry('p1', ctl.url));
    const ctrl = new AbortController();
    setTimeout(() => ctrl.abort(), 150);
    await expect(pause(gw, 5000, ctrl.signal)).rejects.toThrow();
    await sleep(2200);
    expect(ctl.lines).toEqual([]);
    const audit = await commandAudit(gw);
    expect(audit.result).toBe('error');
    expect(audit.error).toMatch(/not sent/);
  });

  it('reads are not commands: a deadline header changes nothing for them', async () => {
    const ctl = await slowController(500);
    const gw = await setup(entry('p1', ctl.url));
    const r = await consoleFetch(`${gw.url}/machines/p1/status`, {
      headers: { 'X-Shopdeck-Deadline': '100' },
    });
    expect(r.status).toBe(200);
  });
});

describe('commandDeadlineMs', () => {
  it('takes a positive whole number of ms, caps it, and falls back when absent or not a number', () => {
    expect(commandDeadlineMs('2500', 15_000)).toBe(2500);
    expect(commandDeadlineMs(' 300 ', 15_000)).toBe(300);
    expect(commandDeadlineMs(undefined, 15_000)).toBe(15_000);
    expect(commandDeadlineMs(undefined, null)).toBeNull();
    for (const bad of ['', 'soon', '-5', '0', '1.5e3x', 'Infinity', 'NaN'])
      expect(commandDeadlineMs(bad, 15_000)).toBe(15_000);
    expect(commandDeadlineMs(['400', '800'], 15_000)).toBe(400);
    expect(commandDeadlineMs('999999999', 15_000)).toBe(MAX_COMMAND_DEADLINE_MS);
    expect(commandDeadlineMs(undefined, 999_999_999)).toBe(MAX_COMMAND_DEADLINE_MS);
  });
});

describe('the gateway’s own failures say so', () => {
  it('a refused WebSocket upgrade carries X-Shopdeck-Gateway too', async () => {
    const ctl = await slowController(0);
    const gw = await setup(entry('p1', ctl.url));
    const port = Number(gw.host.split(':')[1]);
    const res = await new Promise<IncomingMessage>((resolve, reject) => {
      const req = http.request({
        host: '127.0.0.1',
        port,
        path: '/machines/nope/live',
        headers: {
          Connection: 'Upgrade',
          Upgrade: 'websocket',
          'Sec-WebSocket-Version': '13',
          'Sec-WebSocket-Key': 'dGhlIHNhbXBsZSBub25jZQ==',
          Origin: gw.url,
        },
      });
      req.on('response', resolve);
      req.on('upgrade', () => reject(new Error('upgraded')));
      req.on('error', reject);
      req.end();
    });
    res.resume();
    expect(res.statusCode).toBe(404);
    expect(res.headers['x-shopdeck-gateway']).toBe('error');
  });
});
