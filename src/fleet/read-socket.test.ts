import { afterEach, beforeEach, describe, expect, it, vi } from 'vitest';
import { z } from 'zod/mini';
import { onSessionGone } from './auth';
import { LinkError } from './errors';
import { installFakeFetch, type FakeFetch } from './fake-fetch.test-util';
import { HttpClient } from './http';
import { parseAnswer, ReadSocket, startReadSocket } from './read-socket';

/**
 * The page's read socket (read-socket.ts) as HttpClient uses it: reads over the socket while it
 * is open, everything else (and every read it does not answer) over HTTP; never a queue.
 */

class FakeSocket {
  static all: FakeSocket[] = [];
  readonly OPEN = 1;
  readyState = 0;
  sent: string[] = [];
  closedWith: number | null = null;
  onopen: (() => void) | null = null;
  onmessage: ((ev: { data: unknown }) => void) | null = null;
  onclose: ((ev?: { code: number }) => void) | null = null;
  constructor(readonly url: string) {
    FakeSocket.all.push(this);
  }
  send(s: string): void {
    this.sent.push(s);
  }
  close(code = 1000): void {
    this.closedWith = code;
    this.readyState = 3;
  }
  // test side
  accept(): void {
    this.readyState = 1;
    this.onopen?.();
  }
  drop(code?: number): void {
    this.readyState = 3;
    this.onclose?.(code === undefined ? undefined : { code });
  }
  say(msg: unknown): void {
    this.onmessage?.({ data: typeof msg === 'string' ? msg : JSON.stringify(msg) });
  }
  asked(): Array<{ id: number; url?: string; headers?: Record<string, string>; cancel?: number }> {
    return this.sent.map((s) => JSON.parse(s) as { id: number; url?: string });
  }
}

const Status = z.object({ state: z.string() });
/** The console's origin in these tests (tests/setup). */
const O = 'http://shopdeck.test';
let fetch: FakeFetch;
let clock = 0;

beforeEach(() => {
  FakeSocket.all = [];
  clock = 1_000_000;
  vi.stubGlobal('WebSocket', FakeSocket);
  fetch = installFakeFetch();
});
afterEach(() => {
  startReadSocket(null);
  vi.useRealTimers();
  vi.unstubAllGlobals();
});

function openSocket(): { reads: ReadSocket; sock: FakeSocket } {
  const reads = startReadSocket(
    new ReadSocket(
      'ws://console/api/reads',
      () => clock,
      () => 0.5,
    ),
  );
  if (!reads) throw new Error('no read socket');
  // The first read opens it (and goes over HTTP meanwhile).
  const c = new HttpClient({ machineId: 'm1' });
  void c.raw({ path: '/warmup' }).catch(() => undefined);
  fetch.last().answer(200, '{}');
  const sock = FakeSocket.all[0];
  if (!sock) throw new Error('no socket was opened');
  sock.accept();
  return { reads, sock };
}

async function tick(): Promise<void> {
  for (let i = 0; i < 5; i++) await Promise.resolve();
}

describe('HttpClient over the read socket', () => {
  it('while the socket is not open, reads go over HTTP and the socket is opened (once)', async () => {
    startReadSocket(
      new ReadSocket(
        'ws://console/api/reads',
        () => clock,
        () => 0.5,
      ),
    );
    const c = new HttpClient({ machineId: 'm1' });
    const a = c.json({ path: '/status' }, Status);
    const b = c.json({ path: '/status' }, Status);
    expect(fetch.calls.map((x) => x.url)).toEqual([`${O}/machines/m1/status`, `${O}/machines/m1/status`]);
    expect(FakeSocket.all.length).toBe(1);
    for (const call of fetch.calls) call.answer(200, '{"state":"idle"}');
    await expect(a).resolves.toEqual({ state: 'idle' });
    await expect(b).resolves.toEqual({ state: 'idle' });
  });

  it('an open socket carries the read (URL, console header) and its answer is parsed as over HTTP', async () => {
    const { sock } = openSocket();
    const c = new HttpClient({ machineId: 'm1', headers: () => ({ 'X-Extra': 'yes' }) });
    const got = c.json({ path: '/status', query: { full: 1 } }, Status);
    await tick();
    const ask = sock.asked().at(-1);
    expect(ask?.url).toBe('/machines/m1/status?full=1');
    expect(ask?.headers).toMatchObject({ 'X-Shopdeck': '1', 'X-Extra': 'yes' });
    sock.say({
      id: ask?.id,
      status: 200,
      headers: { 'content-type': 'application/json' },
      body: '{"state":"run"}',
    });
    await expect(got).resolves.toEqual({ state: 'run' });
    expect(fetch.calls.length).toBe(1); // the warm-up only
  });

  it('the gateway’s own refusal on the socket is told apart as over HTTP', async () => {
    const { sock } = openSocket();
    const c = new HttpClient({ machineId: 'm1' });
    const got = c.json({ path: '/status' }, Status).catch((e: unknown) => e);
    await tick();
    sock.say({
      id: sock.asked().at(-1)?.id,
      status: 503,
      headers: { 'x-shopdeck-gateway': 'error', 'content-type': 'application/json' },
      body: '{"error":"m1 cannot be reached on the network","gateway":true}',
    });
    const e = await got;
    expect(e).toBeInstanceOf(LinkError);
    expect((e as LinkError).kind).toBe('network');
    expect((e as LinkError).message).toBe('m1 cannot be reached on the network');
  });

  it('commands, bodies, other methods and binary answers never go over the socket', async () => {
    const { sock } = openSocket();
    const c = new HttpClient({ machineId: 'm1' });
    const before = sock.sent.length;
    void c.raw({ path: '/cmd', commandId: 'c-1' }).catch(() => undefined);
    void c.raw({ method: 'POST', path: '/job', json: { a: 1 } }).catch(() => undefined);
    void c.raw({ method: 'DELETE', path: '/file' }).catch(() => undefined);
    void c.blob({ path: '/thumb.png' }).catch(() => undefined);
    await tick();
    expect(sock.sent.length).toBe(before);
    expect(fetch.calls.slice(1).map((x) => `${x.method} ${x.url}`)).toEqual([
      `GET ${O}/machines/m1/cmd`,
      `POST ${O}/machines/m1/job`,
      `DELETE ${O}/machines/m1/file`,
      `GET ${O}/machines/m1/thumb.png`,
    ]);
  });

  it('a read the gateway did not send ("fallback": too many at once, a command) is read over HTTP', async () => {
    const { sock } = openSocket();
    const c = new HttpClient({ machineId: 'm1' });
    const got = c.json({ path: '/big' }, Status);
    await tick();
    sock.say({ id: sock.asked().at(-1)?.id, fallback: 'too many reads at once' });
    await tick();
    expect(fetch.last().url).toBe(`${O}/machines/m1/big`);
    fetch.last().answer(200, '{"state":"big"}');
    await expect(got).resolves.toEqual({ state: 'big' });
  });

  it('a read waiting when the socket closes fails as a broken connection and is not sent again; the socket opens again after 1 s, not before', async () => {
    const { sock } = openSocket();
    const c = new HttpClient({ machineId: 'm1' });
    const got = c.json({ path: '/rr_reply' }, Status).catch((e: unknown) => e);
    await tick();
    sock.drop();
    const e = await got;
    expect(e).toBeInstanceOf(LinkError);
    expect((e as LinkError).kind).toBe('network');
    expect((e as LinkError).message).toMatch(/connection to the console server broke/);
    // Never asked again over HTTP: the read may have been consumed (RepRapFirmware's rr_reply).
    expect(fetch.calls.length).toBe(1); // the warm-up only
    void c.raw({ path: '/a' }).catch(() => undefined);
    expect(FakeSocket.all.length).toBe(1);
    clock += 1000;
    void c.raw({ path: '/b' }).catch(() => undefined);
    expect(FakeSocket.all.length).toBe(2);
  });

  it('a refused socket is tried again later and later (1 s, 2 s, 4 s … 30 s)', () => {
    const reads = startReadSocket(
      new ReadSocket(
        'ws://console/api/reads',
        () => clock,
        () => 1,
      ),
    );
    const ctl = new AbortController();
    const waits: number[] = [];
    for (let i = 0; i < 7; i++) {
      expect(reads?.read('/machines/m1/s', {}, ctl.signal)).toBeNull();
      const sock = FakeSocket.all.at(-1);
      sock?.drop(); // closed before it opened: refused
      const opened = FakeSocket.all.length;
      let waited = 0;
      while (FakeSocket.all.length === opened) {
        clock += 500;
        waited += 500;
        void reads?.read('/machines/m1/s', {}, ctl.signal);
      }
      waits.push(waited);
    }
    expect(waits).toEqual([1000, 2000, 4000, 8000, 16000, 30000, 30000]);
  });

  it('a timeout gives the read up: the gateway is told to drop it, a late answer is ignored', async () => {
    vi.useFakeTimers();
    const { sock } = openSocket();
    const c = new HttpClient({ machineId: 'm1', timeoutMs: 2000 });
    const got = c.json({ path: '/slow' }, Status).catch((e: unknown) => e);
    await tick();
    const id = sock.asked().at(-1)?.id;
    await vi.advanceTimersByTimeAsync(2000);
    const e = await got;
    expect((e as LinkError).kind).toBe('timeout');
    expect(sock.asked().at(-1)).toEqual({ cancel: id });
    sock.say({ id, status: 200, headers: {}, body: '{"state":"late"}' });
    expect(fetch.calls.length).toBe(1); // not read again over HTTP either
  });

  it('a malformed message from the gateway closes the socket; a waiting read fails, not sent again', async () => {
    const { sock } = openSocket();
    const c = new HttpClient({ machineId: 'm1' });
    const got = c.json({ path: '/status' }, Status).catch((e: unknown) => e);
    await tick();
    sock.say('<html>not the gateway</html>');
    expect(sock.closedWith).toBe(1002);
    expect(((await got) as LinkError).kind).toBe('network');
    expect(fetch.calls.length).toBe(1);
  });
});

describe('parseAnswer', () => {
  it('takes the two shapes the gateway sends and nothing else', () => {
    expect(parseAnswer('{"id":3,"fallback":"busy"}')).toEqual({ id: 3, answer: null });
    const a = parseAnswer('{"id":4,"status":404,"headers":{"content-type":"text/plain"},"body":"no"}');
    expect(a?.answer?.status).toBe(404);
    expect(a?.answer?.headers.get('content-type')).toBe('text/plain');
    for (const bad of [
      '{"id":"4","status":200,"headers":{},"body":""}',
      '{"id":4,"status":200,"headers":{"x":1},"body":""}',
      '{"id":4,"status":200,"headers":{},"body":{}}',
      '{"id":4,"status":42,"headers":{},"body":""}',
      '{"id":4,"status":200,"body":""}',
      '[1,2]',
      'null',
      'not json',
    ])
      expect(parseAnswer(bad), bad).toBeNull();
    expect(parseAnswer(new ArrayBuffer(2))).toBeNull();
  });
});

describe('the read socket and the console session (issue 33)', () => {
  for (const [code, gone] of [
    [4401, true],
    [1006, false],
    [1001, false],
  ] as const)
    it(`closed ${code}: the page ${gone ? 'hears its session is gone' : 'does not take it for a sign-out'}`, () => {
      const { sock } = openSocket();
      const heard = vi.fn();
      const stop = onSessionGone(heard);
      try {
        sock.drop(code);
        expect(heard).toHaveBeenCalledTimes(gone ? 1 : 0);
      } finally {
        stop();
      }
    });
});
