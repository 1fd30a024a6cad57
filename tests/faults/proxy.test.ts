import http from 'node:http';
import net from 'node:net';
import { afterEach, describe, expect, it } from 'vitest';
import { startFaultProxy, type FaultProxy } from './proxy';

/** The fault proxy itself, against a raw TCP target and an HTTP target, on real sockets. */

interface Target {
  port: number;
  /** Everything each accepted connection sent, in order of connection. */
  received: string[];
  connections: number;
  /** What the target writes back for each chunk: an echo, or a fixed answer. */
  answer: (chunk: string) => string;
  close(): Promise<void>;
}

async function startTarget(): Promise<Target> {
  const sockets = new Set<net.Socket>();
  const t: Target = {
    port: 0,
    received: [],
    connections: 0,
    answer: (c) => `echo:${c}`,
    close: async () => undefined,
  };
  const server = net.createServer((s) => {
    const i = t.connections++;
    t.received[i] = '';
    sockets.add(s);
    s.on('data', (d: Buffer) => {
      t.received[i] += d.toString('utf8');
      s.write(t.answer(d.toString('utf8')));
    });
    s.on('error', () => undefined);
    s.on('close', () => sockets.delete(s));
  });
  await new Promise<void>((r) => server.listen(0, '127.0.0.1', () => r()));
  t.port = (server.address() as net.AddressInfo).port;
  t.close = () =>
    new Promise<void>((r) => {
      for (const s of sockets) s.destroy();
      server.close(() => r());
    });
  return t;
}

interface Client {
  sock: net.Socket;
  data: () => string;
  closed: () => boolean;
  error: () => NodeJS.ErrnoException | null;
}

function connect(port: number): Promise<Client> {
  return new Promise((resolve, reject) => {
    let data = '';
    let closed = false;
    let error: NodeJS.ErrnoException | null = null;
    const sock = net.connect({ host: '127.0.0.1', port });
    sock.on('data', (d: Buffer) => (data += d.toString('utf8')));
    sock.on('close', () => (closed = true));
    sock.once('error', (e: NodeJS.ErrnoException) => {
      error = e;
      reject(e);
    });
    sock.on('error', () => undefined);
    sock.once('connect', () => resolve({ sock, data: () => data, closed: () => closed, error: () => error }));
  });
}

const sleep = (ms: number) => new Promise((r) => setTimeout(r, ms));

async function until(cond: () => boolean, ms = 2000): Promise<void> {
  const end = Date.now() + ms;
  while (!cond()) {
    if (Date.now() > end) throw new Error('condition not met in time');
    await sleep(10);
  }
}

const cleanups: Array<() => Promise<void> | void> = [];
afterEach(async () => {
  for (const c of cleanups.splice(0).reverse()) await c();
});

async function rig(): Promise<{ target: Target; proxy: FaultProxy }> {
  const target = await startTarget();
  cleanups.push(() => target.close());
  const proxy = await startFaultProxy({ targetPort: target.port });
  cleanups.push(() => proxy.close());
  return { target, proxy };
}

describe('fault proxy', () => {
  it('pass: forwards both ways and counts connections and bytes', async () => {
    const { proxy } = await rig();
    const server = http.createServer((_req, res) => res.end('hello through the proxy'));
    await new Promise<void>((r) => server.listen(0, '127.0.0.1', () => r()));
    cleanups.push(() => new Promise<void>((r) => server.close(() => r())));
    const p2 = await startFaultProxy({ targetPort: (server.address() as net.AddressInfo).port });
    cleanups.push(() => p2.close());
    const res = await fetch(`${p2.url()}/x`);
    expect(await res.text()).toBe('hello through the proxy');
    const s = p2.stats();
    expect(s.connections).toBe(1);
    expect(s.bytesUp).toBeGreaterThan(20);
    expect(s.bytesDown).toBeGreaterThan(20);

    const c = await connect(proxy.port);
    c.sock.write('a');
    await until(() => c.data() === 'echo:a');
    expect(proxy.stats()).toMatchObject({ connections: 1, open: 1, bytesUp: 1, bytesDown: 6 });
    proxy.resetStats();
    expect(proxy.stats()).toMatchObject({ connections: 0, bytesUp: 0, open: 1 });
  });

  it('refuse: the port is closed and open connections are reset; pass opens it again on the same port', async () => {
    const { proxy, target } = await rig();
    const c = await connect(proxy.port);
    const port = proxy.port;
    await proxy.set({ kind: 'refuse' });
    await until(() => c.closed());
    await expect(connect(port)).rejects.toMatchObject({ code: 'ECONNREFUSED' });
    await proxy.set({ kind: 'pass' });
    expect(proxy.port).toBe(port);
    const d = await connect(port);
    d.sock.write('b');
    await until(() => d.data() === 'echo:b');
    expect(target.received.at(-1)).toBe('b');
  });

  it('silent: accepts and reads, answers nothing, closes nothing; held data is delivered when it ends', async () => {
    const { proxy, target } = await rig();
    const c = await connect(proxy.port);
    c.sock.write('1');
    await until(() => c.data() === 'echo:1');
    await proxy.set({ kind: 'silent' });
    c.sock.write('2');
    const fresh = await connect(proxy.port);
    fresh.sock.write('n');
    await sleep(300);
    expect(c.data()).toBe('echo:1');
    expect(c.closed()).toBe(false);
    expect(fresh.closed()).toBe(false);
    expect(target.received).toEqual(['1']);
    // The connection born during the silence has not reached the target at all.
    expect(target.connections).toBe(1);
    await proxy.set({ kind: 'pass' });
    await until(() => c.data() === 'echo:1echo:2' && fresh.data() === 'echo:n');
    expect(target.received).toEqual(['12', 'n']);
    expect(proxy.stats().heldDelivered).toBeGreaterThan(0);
  });

  it('silent: like TCP, a graceful close still delivers after the silence, a reset or a never-connected client does not', async () => {
    const { proxy, target } = await rig();
    const fin = await connect(proxy.port);
    const rst = await connect(proxy.port);
    await until(() => target.connections === 2);
    await proxy.set({ kind: 'silent' });
    const born = await connect(proxy.port);
    fin.sock.write('fin-data');
    rst.sock.write('rst-data');
    born.sock.write('born-data');
    await sleep(100);
    fin.sock.end();
    rst.sock.resetAndDestroy();
    born.sock.destroy();
    await sleep(200);
    expect(target.received).toEqual(['', '']);
    await proxy.set({ kind: 'pass' });
    await sleep(300);
    expect(target.received).toEqual(['fin-data', '']);
    expect(target.connections).toBe(2);
    const s = proxy.stats();
    expect(s.finWhileHeld).toBe(1);
    expect(s.resetWhileHeld).toBe(1);
    expect(s.heldDropped).toBe('rst-data'.length + 'born-data'.length);
  });

  it('reset: open connections are reset, new ones reset on accept', async () => {
    const { proxy, target } = await rig();
    const c = await connect(proxy.port);
    await until(() => target.connections === 1);
    await proxy.set({ kind: 'reset' });
    await until(() => c.closed());
    expect(c.error()?.code).toBe('ECONNRESET');
    const d = await connect(proxy.port).catch((e: NodeJS.ErrnoException) => e);
    if (!(d instanceof Error)) {
      d.sock.write('x');
      await until(() => d.closed());
      expect(d.data()).toBe('');
    }
    expect(proxy.stats().resetOnAccept).toBe(1);
    expect(target.connections).toBe(1);
    await proxy.set({ kind: 'pass' });
    const e = await connect(proxy.port);
    e.sock.write('y');
    await until(() => e.data() === 'echo:y');
  });

  it('latency: each way, in order', async () => {
    const { proxy } = await rig();
    await proxy.set({ kind: 'latency', ms: 150 });
    const c = await connect(proxy.port);
    const t0 = Date.now();
    c.sock.write('a');
    await sleep(20);
    c.sock.write('b');
    await until(() => c.data() === 'echo:aecho:b');
    const took = Date.now() - t0;
    expect(took).toBeGreaterThanOrEqual(300);
    expect(took).toBeLessThan(1500);
    await proxy.set({ kind: 'pass' });
    const t1 = Date.now();
    c.sock.write('c');
    await until(() => c.data().endsWith('echo:c'));
    expect(Date.now() - t1).toBeLessThan(150);
  });

  it('truncate/close: the first bytes of each answer, then the connection is closed', async () => {
    const { proxy, target } = await rig();
    target.answer = () => 'hello world, a long answer';
    await proxy.set({ kind: 'truncate', bytes: 5, then: 'close' });
    const c = await connect(proxy.port);
    c.sock.write('q');
    await until(() => c.closed());
    expect(c.data()).toBe('hello');
    expect(proxy.stats().truncated).toBe(1);
  });

  it('truncate/hold: the first bytes of each answer, then nothing, the connection open', async () => {
    const { proxy, target } = await rig();
    target.answer = () => 'hello world';
    await proxy.set({ kind: 'truncate', bytes: 5, then: 'hold' });
    const c = await connect(proxy.port);
    c.sock.write('q');
    await sleep(300);
    expect(c.data()).toBe('hello');
    expect(c.closed()).toBe(false);
    c.sock.write('r');
    await sleep(200);
    expect(c.data()).toBe('hello');
    // Leaving truncate ends a connection that was cut in the middle of an answer.
    await proxy.set({ kind: 'pass' });
    await until(() => c.closed());
  });

  it('restart: everything closed, refused for a while, then passing again by itself', async () => {
    const { proxy } = await rig();
    const c = await connect(proxy.port);
    await proxy.set({ kind: 'restart', downMs: 400 });
    await until(() => c.closed());
    await expect(connect(proxy.port)).rejects.toMatchObject({ code: 'ECONNREFUSED' });
    await sleep(500);
    expect(proxy.mode.kind).toBe('pass');
    const d = await connect(proxy.port);
    d.sock.write('z');
    await until(() => d.data() === 'echo:z');
  });

  it('a later mode cancels a pending restart', async () => {
    const { proxy } = await rig();
    await proxy.set({ kind: 'restart', downMs: 200 });
    await proxy.set({ kind: 'refuse' });
    await sleep(350);
    expect(proxy.mode.kind).toBe('refuse');
    await expect(connect(proxy.port)).rejects.toMatchObject({ code: 'ECONNREFUSED' });
  });
});
