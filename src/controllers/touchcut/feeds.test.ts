import { afterEach, beforeEach, describe, expect, it, vi } from 'vitest';
import { LinkError } from '../../fleet/errors';
import { createContext } from '../../fleet/fleet';
import { KernelSession, Lifecycle } from '../../fleet/kernel';
import { alwaysVisible, type Visibility } from '../../fleet/link';
import type { TouchcutClient } from './client';
import {
  mergeChanged,
  MonitorFeed,
  ScreenshotFeed,
  SCREENSHOT_MIN_GAP_MS,
  SCREENSHOT_STARTS_KEPT,
  THUMBNAIL_INTERVAL_MS,
  type DeclarePoll,
  type FeedHost,
} from './feeds';

function fakeVisibility() {
  let hidden = false;
  const subs = new Set<() => void>();
  const v: Visibility & { set(h: boolean): void } = {
    hidden: () => hidden,
    subscribe: (fn) => {
      subs.add(fn);
      return () => subs.delete(fn);
    },
    set(h) {
      hidden = h;
      for (const fn of subs) fn();
    },
  };
  return v;
}

function host(client: Partial<TouchcutClient>, visibility = fakeVisibility(), extra: Partial<FeedHost> = {}) {
  const life = new Lifecycle();
  life.start();
  return {
    visibility,
    life,
    h: {
      client: client as TouchcutClient,
      visibility,
      now: () => Date.now(),
      units: () => 'default' as const,
      canRequest: () => true,
      authFailed: vi.fn(),
      life,
      ...extra,
    } satisfies FeedHost,
  };
}

/** The smallest kernel session: feeds declare their polls on it, as TouchcutSession does. */
class Kernel extends KernelSession {
  readonly commands = {};
  readonly declare: DeclarePoll = (spec) => this.poll(spec);
}

function kernel(): Kernel {
  return new Kernel(
    createContext(
      { id: 'tc', name: 'Plasma', kind: 'touchcut', simulated: true },
      { visibility: alwaysVisible },
    ),
  );
}

beforeEach(() => vi.useFakeTimers());
afterEach(() => vi.useRealTimers());

describe('screenshot limiter', () => {
  it('never asks more than once per second, even with many viewers and slow answers', async () => {
    let latency = 100;
    const screenshot = vi.fn(async () => {
      await new Promise((r) => setTimeout(r, latency));
      return { blob: new Blob([new Uint8Array([1])]), bytes: 1 };
    });
    const { h } = host({ screenshot });
    const feed = new ScreenshotFeed(h);
    const a = feed.subscribe();
    const b = feed.subscribe(); // a second viewer (full-screen) does not double the rate
    const c = feed.subscribe(THUMBNAIL_INTERVAL_MS); // a fleet tile
    await vi.advanceTimersByTimeAsync(10_000);
    latency = 1500; // slower than the gap: requests must not overlap
    await vi.advanceTimersByTimeAsync(10_000);
    const starts = feed.starts;
    expect(starts.length).toBeGreaterThanOrEqual(15);
    expect(starts.length).toBeLessThanOrEqual(21);
    for (let i = 1; i < starts.length; i++)
      expect((starts[i] ?? 0) - (starts[i - 1] ?? 0)).toBeGreaterThanOrEqual(SCREENSHOT_MIN_GAP_MS);
    expect(feed.store.getState().blob).not.toBeNull();
    a();
    b();
    c();
    const n = screenshot.mock.calls.length;
    await vi.advanceTimersByTimeAsync(10_000);
    expect(screenshot.mock.calls.length).toBe(n);
  });

  it('keeps only the newest start times however long it runs (a wall screen runs for weeks)', async () => {
    const screenshot = vi.fn(async () => ({ blob: new Blob([new Uint8Array([1])]), bytes: 1 }));
    const { h } = host({ screenshot });
    const feed = new ScreenshotFeed(h);
    const off = feed.subscribe();
    const n = SCREENSHOT_STARTS_KEPT * 5;
    await vi.advanceTimersByTimeAsync(n * SCREENSHOT_MIN_GAP_MS);
    off();
    expect(feed.requests).toBeGreaterThanOrEqual(n);
    expect(feed.starts).toHaveLength(SCREENSHOT_STARTS_KEPT);
    // The newest ones: the last start is the last request's.
    expect(Date.now() - (feed.starts.at(-1) ?? 0)).toBeLessThanOrEqual(SCREENSHOT_MIN_GAP_MS);
    expect((feed.starts.at(-1) ?? 0) - (feed.starts[0] ?? 0)).toBe(
      (SCREENSHOT_STARTS_KEPT - 1) * SCREENSHOT_MIN_GAP_MS,
    );
  });

  it('sends nothing while the page is hidden and resumes when it is visible', async () => {
    const screenshot = vi.fn(async () => ({ blob: new Blob([]), bytes: 0 }));
    const { h, visibility } = host({ screenshot });
    const feed = new ScreenshotFeed(h);
    feed.subscribe();
    await vi.advanceTimersByTimeAsync(2500);
    const seen = screenshot.mock.calls.length;
    expect(seen).toBe(3);
    visibility.set(true);
    await vi.advanceTimersByTimeAsync(60_000);
    expect(screenshot.mock.calls.length).toBe(seen);
    visibility.set(false);
    await vi.advanceTimersByTimeAsync(10);
    expect(screenshot.mock.calls.length).toBe(seen + 1);
  });

  it('a tile alone refreshes every 10 s', async () => {
    const screenshot = vi.fn(async () => ({ blob: new Blob([]), bytes: 0 }));
    const feed = new ScreenshotFeed(host({ screenshot }).h);
    feed.subscribe(THUMBNAIL_INTERVAL_MS);
    await vi.advanceTimersByTimeAsync(30_500);
    expect(screenshot.mock.calls.length).toBe(4); // 0, 10, 20, 30 s
  });

  it('sends nothing while the machine needs a login, and hands a 401 to the session', async () => {
    let allowed = false;
    const screenshot = vi.fn(async () => {
      throw new LinkError('http', 'nope', { status: 401 });
    });
    const { h } = host({ screenshot }, fakeVisibility(), { canRequest: () => allowed });
    const feed = new ScreenshotFeed(h);
    feed.subscribe();
    await vi.advanceTimersByTimeAsync(10_000);
    expect(screenshot).not.toHaveBeenCalled();
    allowed = true;
    await vi.advanceTimersByTimeAsync(2500);
    expect(screenshot).toHaveBeenCalledTimes(1);
    expect(h.authFailed).toHaveBeenCalledTimes(1);
    expect(feed.store.getState().error).toBe('nope');
  });
});

describe('monitor feed', () => {
  it('polls about twice a second with the fields on screen, only while someone watches', async () => {
    const monitor = vi.fn(async () => ({
      io: { din: [], dout: [], ain: [], aout: [] },
      axes: [],
      units: 'metric',
    }));
    const k = kernel();
    const feed = new MonitorFeed(host({ monitor }, fakeVisibility(), { life: k.life }).h, k.declare);
    k.start();
    feed.setFields(['axes.*', 'io.din']);
    await vi.advanceTimersByTimeAsync(1000);
    expect(monitor).not.toHaveBeenCalled(); // nobody watches yet
    const release = feed.acquire();
    await vi.advanceTimersByTimeAsync(2000);
    expect(monitor.mock.calls.length).toBeGreaterThanOrEqual(4);
    expect(monitor.mock.calls.length).toBeLessThanOrEqual(5);
    expect(monitor).toHaveBeenLastCalledWith(['axes.*', 'io.din'], 'default', expect.any(AbortSignal));
    expect(feed.store.getState().data?.units).toBe('metric');
    release();
    const n = monitor.mock.calls.length;
    await vi.advanceTimersByTimeAsync(5000);
    expect(monitor.mock.calls.length).toBe(n);
    k.stop();
  });
});

describe('onlyChangedData merge', () => {
  it('merges objects and replaces arrays', () => {
    expect(mergeChanged({ a: { x: 1, y: 2 }, list: [1, 2], keep: true }, { a: { y: 3 }, list: [9] })).toEqual(
      {
        a: { x: 1, y: 3 },
        list: [9],
        keep: true,
      },
    );
  });
});
