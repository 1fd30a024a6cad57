import { mkdirSync, mkdtempSync, rmSync, writeFileSync } from 'node:fs';
import net from 'node:net';
import os from 'node:os';
import path from 'node:path';
import { afterAll, beforeAll, describe, expect, it } from 'vitest';
import { startStub, type Stub } from '../gateway/test-util';
import { createLogger } from './log';
import { createShopdeckServer, type ShopdeckServer } from './server';

/**
 * The body deadline (server/body-deadline.ts) on the real server and real sockets, with the
 * deadlines shortened by the server's options (the defaults are 120 s and 60 s): a streamed
 * upload to a machine may take longer than the deadline; a body the gateway reads itself may not
 * (slow loris), nor may a streamed upload stall.
 */

const BODY_MS = 300;
const STALL_MS = 600;
const work = mkdtempSync(path.join(os.tmpdir(), 'shopdeck-body-'));
let stub: Stub;
let server: ShopdeckServer;
let port = 0;

beforeAll(async () => {
  stub = await startStub();
  const dist = path.join(work, 'dist');
  mkdirSync(dist);
  writeFileSync(path.join(dist, 'index.html'), '<!doctype html><title>t</title>');
  const machinesFile = path.join(work, 'machines.json');
  writeFileSync(
    machinesFile,
    JSON.stringify({
      machines: [
        { id: 'p1', name: 'P1', kind: 'prunt', url: stub.url },
        { id: 'sim', name: 'Simulated', kind: 'prunt', simulated: true },
      ],
    }),
  );
  server = createShopdeckServer({
    distDir: dist,
    host: '127.0.0.1',
    port: 0,
    env: {},
    dataDir: path.join(work, 'data'),
    machinesFile,
    logger: createLogger({ write: () => undefined }),
    bodyTimeoutMs: BODY_MS,
    uploadStallMs: STALL_MS,
  });
  port = (await server.listen()).port;
});

afterAll(async () => {
  await server?.close();
  await stub?.close();
  rmSync(work, { recursive: true, force: true });
});

interface Outcome {
  status: number | null;
  text: string;
  /** How many body bytes were written before the answer or the connection's end. */
  sent: number;
}

/**
 * A request whose body is written `chunk` bytes every `everyMs` (stopping after `stopAfter`
 * chunks when given); resolves when the answer came whole or the connection ended.
 */
function trickle(opts: {
  method: string;
  path: string;
  headers: Record<string, string>;
  size: number;
  chunk: number;
  everyMs: number;
  stopAfter?: number;
  /** Keep sending after the answer, until the server closes the connection. */
  untilClosed?: boolean;
}): Promise<Outcome> {
  return new Promise((resolve) => {
    const sock = net.connect(port, '127.0.0.1');
    let sent = 0;
    let chunks = 0;
    let got = '';
    let timer: NodeJS.Timeout | null = null;
    const head =
      `${opts.method} ${opts.path} HTTP/1.1\r\nHost: 127.0.0.1:${port}\r\n` +
      Object.entries({ ...opts.headers, 'Content-Length': String(opts.size) })
        .map(([k, v]) => `${k}: ${v}\r\n`)
        .join('') +
      '\r\n';
    const finish = (): void => {
      if (timer) clearInterval(timer);
      timer = null;
      const m = /^HTTP\/1\.1 (\d{3})/.exec(got);
      const body = got.split('\r\n\r\n').slice(1).join('\r\n\r\n');
      sock.destroy();
      resolve({ status: m ? Number(m[1]) : null, text: body, sent });
    };
    sock.on('data', (d: Buffer) => {
      got += d.toString('latin1');
      const at = got.indexOf('\r\n\r\n');
      if (at < 0) return;
      const headers = got.slice(0, at);
      const body = got.slice(at + 4);
      const cl = /content-length: (\d+)/i.exec(headers);
      const whole = cl ? body.length >= Number(cl[1]) : body.endsWith('0\r\n\r\n');
      if (whole && !opts.untilClosed) finish();
    });
    sock.on('close', finish);
    sock.on('error', () => undefined);
    sock.write(head);
    timer = setInterval(() => {
      if (sock.destroyed) return;
      if (opts.stopAfter !== undefined && chunks >= opts.stopAfter) return;
      const n = Math.min(opts.chunk, opts.size - sent);
      if (n <= 0) return;
      sock.write(Buffer.alloc(n, 0x41));
      sent += n;
      chunks++;
    }, opts.everyMs);
  });
}

describe('request bodies: no deadline for a streamed upload, a bound for everything else', () => {
  it('a streamed upload to a machine that takes several times the body deadline arrives whole', async () => {
    const size = 16 * 1024;
    const started = Date.now();
    const r = await trickle({
      method: 'PUT',
      path: '/machines/p1/uploads/slow.gcode',
      headers: { 'X-Shopdeck': '1', 'Content-Type': 'application/octet-stream' },
      size,
      chunk: 1024,
      everyMs: 100, // 16 chunks: about 1.6 s, five times BODY_MS
    });
    expect(Date.now() - started).toBeGreaterThan(BODY_MS * 3);
    expect(r.status).toBe(200);
    expect(r.sent).toBe(size);
    const seen = stub.seen.find((s) => s.url === '/uploads/slow.gcode');
    expect(seen?.method).toBe('PUT');
    expect(seen?.body.length).toBe(size);
  });

  it('the same upload to a simulated machine arrives whole too', async () => {
    const started = Date.now();
    const r = await trickle({
      method: 'PUT',
      path: '/machines/sim/uploads/slow.gcode',
      headers: { 'X-Shopdeck': '1', 'Content-Type': 'application/octet-stream' },
      size: 16 * 1024,
      chunk: 1024,
      everyMs: 100,
    });
    expect(Date.now() - started).toBeGreaterThan(BODY_MS * 3);
    expect(r.sent).toBe(16 * 1024);
    expect(r.status).toBeGreaterThanOrEqual(200);
    expect(r.status).toBeLessThan(300);
  });

  it('a body the gateway reads itself (the settings) trickled byte by byte is cut: 408, the connection closed', async () => {
    const r = await trickle({
      method: 'PUT',
      path: '/api/settings',
      headers: { 'X-Shopdeck': '1', 'Content-Type': 'application/json' },
      size: 200,
      chunk: 1,
      everyMs: 50, // the whole body would take 10 s
    });
    expect(r.status).toBe(408);
    expect(r.text).toMatch(/did not arrive in time/);
    expect(r.sent).toBeLessThan(200);
  });

  it('a body the gateway did not need (answered at once) cannot hold the connection by trickling on', async () => {
    const r = await trickle({
      method: 'POST',
      path: '/api/login', // open mode: answered 400 without reading the body
      headers: { 'X-Shopdeck': '1', 'Content-Type': 'application/json' },
      size: 200,
      chunk: 1,
      everyMs: 50,
      untilClosed: true,
    });
    expect(r.status).toBe(400);
    expect(r.sent).toBeLessThan(200);
  });

  it('a streamed upload that stops sending is cut, and nothing is passed on as a whole file', async () => {
    const r = await trickle({
      method: 'PUT',
      path: '/machines/p1/uploads/stalled.gcode',
      headers: { 'X-Shopdeck': '1', 'Content-Type': 'application/octet-stream' },
      size: 64 * 1024,
      chunk: 1024,
      everyMs: 50,
      stopAfter: 4,
    });
    expect(r.sent).toBe(4 * 1024);
    expect(r.status === null || r.status >= 400).toBe(true);
    expect(stub.seen.find((s) => s.url === '/uploads/stalled.gcode')).toBeUndefined();
  }, 20_000);
});
