import { ws } from 'msw';
import { setupServer } from 'msw/node';
import { afterAll, afterEach, beforeAll, describe, expect, it, vi } from 'vitest';
import { LinkTracker } from './contract';
import { LinkError } from './errors';
import { createContext } from './fleet';
import { alwaysVisible, SocketLink } from './link';

const link = ws.link('ws://shopdeck.test/machines/m1/*');
const server = setupServer();
beforeAll(() => server.listen({ onUnhandledRequest: 'error' }));
afterEach(() => server.resetHandlers());
afterAll(() => server.close());

const until = async (cond: () => boolean) => {
  for (let i = 0; i < 200 && !cond(); i++) await new Promise((r) => setTimeout(r, 5));
  expect(cond()).toBe(true);
};

describe('SocketLink', () => {
  it('reconnects after the server closes, and never replays what was sent while closed', async () => {
    const received: string[] = [];
    let connections = 0;
    server.use(
      link.addEventListener('connection', ({ client }) => {
        connections++;
        client.addEventListener('message', (e) => received.push(String(e.data)));
        if (connections === 1) setTimeout(() => client.close(1011, 'service down'), 5);
      }),
    );
    const closes: number[] = [];
    const sock = new SocketLink({
      url: () => 'ws://shopdeck.test/machines/m1/ws',
      onMessage: () => undefined,
      onClose: (code) => {
        closes.push(code);
      },
      backoff: { baseMs: 10, maxMs: 20 },
    });
    await until(() => closes.length === 1);
    expect(sock.open).toBe(false);
    expect(sock.send('PAUSE')).toBe(false); // not buffered
    await until(() => connections === 2 && sock.open);
    expect(sock.send('hello')).toBe(true);
    await until(() => received.length === 1);
    expect(received).toEqual(['hello']);
    sock.close();
  });
});

describe('LinkTracker', () => {
  it('goes reconnecting, then offline after repeated failures, with growing delays', () => {
    const ctx = createContext(
      { id: 'm1', name: 'M1', kind: 'xtool', simulated: false },
      { visibility: alwaysVisible, now: () => 1000 },
    );
    const t = new LinkTracker(ctx);
    vi.spyOn(Math, 'random').mockReturnValue(1);
    const d1 = t.fail(new LinkError('network', 'down'));
    expect(ctx.snapshot.getState().link).toBe('reconnecting');
    const d2 = t.fail(new LinkError('timeout', 'slow'));
    expect(d2).toBeGreaterThan(d1);
    t.fail(new LinkError('network', 'down'));
    expect(ctx.snapshot.getState().link).toBe('offline');
    expect(ctx.snapshot.getState().activity).toBe('offline');
    t.ok({ activity: 'idle' });
    expect(ctx.snapshot.getState()).toMatchObject({
      link: 'online',
      problem: null,
      activity: 'idle',
      updatedAt: 1000,
    });
    t.fail(new LinkError('protocol', 'bad', { path: 'progress' }));
    expect(ctx.snapshot.getState()).toMatchObject({ link: 'protocol-error', problem: { path: 'progress' } });
    vi.restoreAllMocks();
  });
});

describe('SocketLink coalesce', () => {
  it('hands a burst over in one batch per frame, in order, and nothing after close()', async () => {
    const sent: Array<(ev: { data: string }) => void> = [];
    class FakeSocket {
      readyState = 1;
      onopen: (() => void) | null = null;
      onmessage: ((ev: { data: string }) => void) | null = null;
      onclose: (() => void) | null = null;
      onerror: (() => void) | null = null;
      constructor() {
        sent.push((ev) => this.onmessage?.(ev));
      }
      send(): void {}
      close(): void {}
    }
    const original = globalThis.WebSocket;
    globalThis.WebSocket = FakeSocket as unknown as typeof WebSocket;
    vi.useFakeTimers();
    try {
      const batches: string[][] = [];
      let current: string[] = [];
      const link = new SocketLink({
        url: () => 'ws://x/',
        coalesce: true,
        onMessage: (m) => current.push(m),
      });
      const push = sent[0]!;
      for (let i = 0; i < 1000; i++) push({ data: `m${i}` });
      expect(current).toEqual([]); // nothing handed over synchronously
      await vi.advanceTimersByTimeAsync(20);
      batches.push(current);
      current = [];
      expect(batches[0]).toEqual(Array.from({ length: 1000 }, (_, i) => `m${i}`));
      push({ data: 'late' });
      link.close();
      await vi.advanceTimersByTimeAsync(20);
      expect(current).toEqual([]);
    } finally {
      vi.useRealTimers();
      globalThis.WebSocket = original;
    }
  });
});
