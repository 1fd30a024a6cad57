import { afterEach, beforeEach, describe, expect, it, vi } from 'vitest';
import { backoffDelay, gridDelay, HIDDEN_POLL_MS, Poller, type Visibility } from './link';

describe('backoffDelay', () => {
  it('grows exponentially from about 1 s and caps at 30 s', () => {
    const noJitter = { random: () => 1 };
    expect([0, 1, 2, 3, 4, 5, 6, 10].map((a) => backoffDelay(a, noJitter))).toEqual([
      1000, 2000, 4000, 8000, 16000, 30000, 30000, 30000,
    ]);
  });
  it('adds jitter below the nominal delay so machines do not reconnect in lockstep', () => {
    const low = backoffDelay(3, { random: () => 0 });
    const high = backoffDelay(3, { random: () => 1 });
    expect(low).toBeLessThan(high);
    expect(low).toBeGreaterThanOrEqual(8000 * 0.7);
  });
});

function fakeVisibility(): Visibility & { setHidden(h: boolean): void } {
  let hidden = false;
  const subs = new Set<() => void>();
  return {
    hidden: () => hidden,
    subscribe: (fn) => {
      subs.add(fn);
      return () => subs.delete(fn);
    },
    setHidden(h) {
      hidden = h;
      subs.forEach((f) => f());
    },
  };
}

describe('gridDelay', () => {
  it('lands on a multiple of the period, half a period to one and a half from now', () => {
    expect(gridDelay(10_000, 1000)).toBe(1000);
    expect(gridDelay(10_499, 1000)).toBe(501);
    expect(gridDelay(10_500, 1000)).toBe(500);
    expect(gridDelay(10_999, 1000)).toBe(1001);
    for (const now of [0, 1, 333, 12_345, 1_700_000_000_123]) {
      const d = gridDelay(now, 2000);
      expect((now + d) % 2000).toBe(0);
      expect(d).toBeGreaterThanOrEqual(1000);
      expect(d).toBeLessThan(3000);
    }
  });
});

describe('Poller', () => {
  beforeEach(() => vi.useFakeTimers());
  afterEach(() => vi.useRealTimers());

  it('aligned: machines polled at the same pace start together on the shared grid', async () => {
    vi.setSystemTime(50_000);
    const starts: Array<[string, number]> = [];
    const make = (name: string, ms: number) => {
      const p = new Poller({
        run: async () => {
          starts.push([name, Date.now()]);
          // Answers take different times: alignment must not drift with them.
          await new Promise((r) => setTimeout(r, name === 'a' ? 37 : 180));
        },
        intervalMs: () => 1000,
        visibility: fakeVisibility(),
        aligned: () => true,
      });
      p.start(ms);
      return p;
    };
    const a = make('a', 0);
    const b = make('b', 420);
    await vi.advanceTimersByTimeAsync(5000);
    a.stop();
    b.stop();
    const after = starts.filter(([, t]) => t >= 52_000);
    expect(after.length).toBeGreaterThanOrEqual(6);
    for (const [, t] of after) expect(t % 1000).toBe(0);
    const times = (n: string) => after.filter(([x]) => x === n).map(([, t]) => t);
    expect(times('a')).toEqual(times('b'));
  });

  it('never starts a poll while the previous one is still running', async () => {
    let running = 0;
    let maxRunning = 0;
    let resolveCurrent: (() => void) | null = null;
    const poller = new Poller({
      run: () =>
        new Promise<void>((resolve) => {
          running++;
          maxRunning = Math.max(maxRunning, running);
          resolveCurrent = () => {
            running--;
            resolve();
          };
        }),
      intervalMs: () => 100,
      visibility: fakeVisibility(),
    });
    poller.start();
    await vi.advanceTimersByTimeAsync(0);
    expect(poller.started).toBe(1);
    // A slow controller: 5 intervals pass, kick() is called; still one poll.
    poller.kick();
    await vi.advanceTimersByTimeAsync(500);
    expect(poller.started).toBe(1);
    (resolveCurrent as unknown as () => void)();
    await vi.advanceTimersByTimeAsync(100);
    expect(poller.started).toBe(2);
    expect(maxRunning).toBe(1);
    poller.stop();
  });

  it('slows to at most one poll per 10 s while the page is hidden, and refreshes when shown', async () => {
    const vis = fakeVisibility();
    const poller = new Poller({ run: async () => undefined, intervalMs: () => 250, visibility: vis });
    poller.start();
    await vi.advanceTimersByTimeAsync(1000);
    const visibleCount = poller.started;
    expect(visibleCount).toBeGreaterThanOrEqual(4);
    vis.setHidden(true);
    await vi.advanceTimersByTimeAsync(250); // the poll scheduled before hiding may still run
    const base = poller.started;
    await vi.advanceTimersByTimeAsync(HIDDEN_POLL_MS * 3);
    expect(poller.started - base).toBeLessThanOrEqual(3);
    expect(poller.started - base).toBeGreaterThanOrEqual(2);
    const beforeShow = poller.started;
    vis.setHidden(false);
    await vi.advanceTimersByTimeAsync(1);
    expect(poller.started).toBe(beforeShow + 1);
    poller.stop();
  });

  it('reports failures and keeps polling at the retry delay', async () => {
    const errors: unknown[] = [];
    let n = 0;
    const poller = new Poller({
      run: async () => {
        n++;
        if (n <= 2) throw new Error(`fail ${n}`);
      },
      intervalMs: () => 100,
      retryDelayMs: (f) => 1000 * f,
      onError: (e) => errors.push(e),
      visibility: fakeVisibility(),
    });
    poller.start();
    await vi.advanceTimersByTimeAsync(0);
    expect(errors).toHaveLength(1);
    await vi.advanceTimersByTimeAsync(999);
    expect(n).toBe(1);
    await vi.advanceTimersByTimeAsync(1);
    expect(n).toBe(2);
    await vi.advanceTimersByTimeAsync(2000);
    expect(n).toBe(3);
    poller.stop();
    await vi.advanceTimersByTimeAsync(5000);
    expect(n).toBe(3);
  });
});
