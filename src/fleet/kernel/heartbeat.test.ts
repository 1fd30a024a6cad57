import { afterEach, beforeEach, describe, expect, it, vi } from 'vitest';
import { SocketLink } from '../link';

/** A WebSocket double: the test opens, feeds and closes it by hand (fake timers drive time). */
class FakeSocket {
  static all: FakeSocket[] = [];
  readyState = 0;
  sent: string[] = [];
  closed = false;
  onopen: (() => void) | null = null;
  onmessage: ((ev: { data: unknown }) => void) | null = null;
  onclose: ((ev: { code: number; reason: string }) => void) | null = null;
  onerror: (() => void) | null = null;
  constructor(readonly url: string) {
    FakeSocket.all.push(this);
  }
  open(): void {
    this.readyState = 1;
    this.onopen?.();
  }
  message(data: string): void {
    this.onmessage?.({ data });
  }
  send(d: string): void {
    this.sent.push(d);
  }
  close(): void {
    this.closed = true;
    this.readyState = 3;
  }
}

beforeEach(() => {
  vi.useFakeTimers();
  FakeSocket.all = [];
  vi.stubGlobal('WebSocket', FakeSocket);
});
afterEach(() => {
  vi.unstubAllGlobals();
  vi.useRealTimers();
});

const last = () => FakeSocket.all[FakeSocket.all.length - 1] as FakeSocket;

describe('SocketLink heartbeat policy', () => {
  it('keeps one timer, not an interval: a message a second for a minute wakes it a few times, and silence is still seen on time (issue 34)', async () => {
    const intervals = vi.spyOn(globalThis, 'setInterval');
    const timeouts = vi.spyOn(globalThis, 'setTimeout');
    const dead: string[] = [];
    const link = new SocketLink({
      url: () => 'ws://shopdeck.test/machines/p1/websocket',
      onMessage: () => undefined,
      heartbeat: { silenceMs: 10_000, onDead: (r) => dead.push(r) },
      backoff: { baseMs: 100, maxMs: 100, jitter: 0 },
    });
    const s = last();
    s.open();
    const before = timeouts.mock.calls.length;
    for (let i = 0; i < 60; i++) {
      s.message('{"status":1}');
      await vi.advanceTimersByTimeAsync(1000);
    }
    expect(intervals).not.toHaveBeenCalled();
    // About one every silenceMs (an interval of min(500, silence / 2) woke 120 times).
    expect(timeouts.mock.calls.length - before).toBeLessThanOrEqual(8);
    expect(dead).toEqual([]);
    // The last message came 1 s ago: dead 10 s after it, not before.
    await vi.advanceTimersByTimeAsync(8_999);
    expect(dead).toEqual([]);
    await vi.advanceTimersByTimeAsync(1);
    expect(dead).toEqual(['No data for 10 s']);
    link.close();
  });

  it('pings after silence, and a missing answer is a dead link: reported, then reconnected', async () => {
    const dead: string[] = [];
    const link = new SocketLink({
      url: () => 'ws://shopdeck.test/machines/d1/machine',
      onMessage: () => undefined,
      heartbeat: { silenceMs: 2000, ping: 'PING\n', answerMs: 2000, onDead: (r) => dead.push(r) },
      backoff: { baseMs: 100, maxMs: 100, jitter: 0 },
    });
    const first = last();
    first.open();
    first.message('{"full":"model"}');
    await vi.advanceTimersByTimeAsync(1500);
    first.message('{"patch":1}'); // data keeps the link alive: no ping yet
    await vi.advanceTimersByTimeAsync(1500);
    expect(first.sent).toEqual([]);
    await vi.advanceTimersByTimeAsync(1000);
    expect(first.sent).toEqual(['PING\n']);
    first.message('PONG\n'); // answered: alive
    await vi.advanceTimersByTimeAsync(1500);
    expect(dead).toEqual([]);
    await vi.advanceTimersByTimeAsync(1000); // silent again: a second ping
    expect(first.sent).toEqual(['PING\n', 'PING\n']);
    await vi.advanceTimersByTimeAsync(2000); // no answer
    expect(dead).toEqual(['No answer to PING']);
    expect(first.closed).toBe(true);
    await vi.advanceTimersByTimeAsync(100);
    expect(FakeSocket.all).toHaveLength(2);
    link.close();
  });

  it('without a ping, silence alone is death; a socket that never speaks is dead too', async () => {
    const dead: string[] = [];
    const link = new SocketLink({
      url: () => 'ws://shopdeck.test/machines/p1/everything',
      onMessage: () => undefined,
      heartbeat: { silenceMs: 10_000, firstMessageMs: 5000, onDead: (r) => dead.push(r) },
      backoff: { baseMs: 100, maxMs: 100, jitter: 0 },
    });
    last().open(); // open, but nothing comes
    await vi.advanceTimersByTimeAsync(5000);
    expect(dead).toEqual(['No data after connecting']);
    await vi.advanceTimersByTimeAsync(100);
    const second = last();
    expect(FakeSocket.all).toHaveLength(2);
    second.open();
    second.message('status');
    await vi.advanceTimersByTimeAsync(9000);
    expect(dead).toHaveLength(1);
    await vi.advanceTimersByTimeAsync(1500); // within one check (500 ms) of the 10 s
    expect(dead).toEqual(['No data after connecting', 'No data for 10 s']);
    link.close();
    await vi.advanceTimersByTimeAsync(60_000);
    expect(FakeSocket.all).toHaveLength(3); // the third (after the second death) — then nothing after close
  });

  it('polls in place of a dead socket until a new socket speaks, and stops polling on close', async () => {
    let polls = 0;
    const link = new SocketLink({
      url: () => 'ws://shopdeck.test/machines/d1/machine',
      onMessage: () => undefined,
      heartbeat: { silenceMs: 1000 },
      fallback: {
        run: async () => void polls++,
        intervalMs: 500,
        visibility: { hidden: () => false, subscribe: () => () => undefined },
      },
      backoff: { baseMs: 3000, maxMs: 3000, jitter: 0 },
    });
    const first = last();
    first.open();
    first.message('x');
    expect(link.polling).toBe(false);
    first.onclose?.({ code: 1006, reason: '' }); // dropped
    expect(link.polling).toBe(true);
    await vi.advanceTimersByTimeAsync(1100);
    expect(polls).toBeGreaterThanOrEqual(2);
    await vi.advanceTimersByTimeAsync(2000); // reconnect due
    const second = last();
    expect(second).not.toBe(first);
    second.open();
    second.message('y');
    expect(link.polling).toBe(false);
    const n = polls;
    await vi.advanceTimersByTimeAsync(400);
    second.message('z');
    await vi.advanceTimersByTimeAsync(400);
    expect(polls).toBe(n);
    link.close();
  });

  it('never holds two sockets: a restart while a reconnect is pending, or a connect while connecting', async () => {
    const link = new SocketLink({
      url: () => 'ws://shopdeck.test/machines/x1/ws',
      onMessage: () => undefined,
      backoff: { baseMs: 1000, maxMs: 1000, jitter: 0 },
    });
    const first = last();
    first.close();
    first.onclose?.({ code: 1006, reason: '' }); // dropped: a reconnect is pending
    link.restart(); // the caller also thinks it is dead
    await vi.advanceTimersByTimeAsync(1000);
    expect(FakeSocket.all).toHaveLength(2); // one reconnect, not two
    const second = last();
    link.connect(); // while the second is still connecting
    expect(second.closed).toBe(true);
    expect(FakeSocket.all.filter((s) => !s.closed)).toHaveLength(1);
    await vi.advanceTimersByTimeAsync(10_000);
    expect(FakeSocket.all.filter((s) => !s.closed)).toHaveLength(1);
    link.close();
  });
});
