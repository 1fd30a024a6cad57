// @vitest-environment happy-dom
import { afterEach, beforeEach, describe, expect, it, vi } from 'vitest';
import { reachStore, retryNow, untilReachable } from './reach';

const failed = (): Promise<never> => Promise.reject(new TypeError('Failed to fetch'));
const ok = (body: string): Promise<string> => Promise.resolve(body);

describe('untilReachable', () => {
  beforeEach(() => {
    vi.useFakeTimers();
    reachStore.setState({ unreachable: false, offline: false, nextTryAt: null });
  });
  afterEach(() => vi.useRealTimers());

  it('says the console is unreachable while there is no answer, tries again backing off, and recovers', async () => {
    const read = vi.fn<() => Promise<string>>();
    read
      .mockImplementationOnce(failed)
      .mockImplementationOnce(failed)
      .mockImplementation(() => ok('fleet'));
    const waits = [1000, 2000];
    const done = untilReachable(read, (attempt) => waits[attempt] ?? 30_000);
    await vi.advanceTimersByTimeAsync(0);
    expect(read).toHaveBeenCalledTimes(1);
    expect(reachStore.getState()).toMatchObject({ unreachable: true, nextTryAt: Date.now() + 1000 });
    await vi.advanceTimersByTimeAsync(999);
    expect(read).toHaveBeenCalledTimes(1);
    await vi.advanceTimersByTimeAsync(1);
    expect(read).toHaveBeenCalledTimes(2);
    expect(reachStore.getState()).toMatchObject({ unreachable: true, nextTryAt: Date.now() + 2000 });
    await vi.advanceTimersByTimeAsync(2000);
    await expect(done).resolves.toBe('fleet');
    expect(read).toHaveBeenCalledTimes(3);
    expect(reachStore.getState()).toEqual({ unreachable: false, offline: false, nextTryAt: null });
  });

  it('tries again at once on "Try now" and when the browser is back online', async () => {
    const read = vi.fn<() => Promise<string>>(failed);
    const done = untilReachable(read, () => 30_000);
    await vi.advanceTimersByTimeAsync(0);
    expect(read).toHaveBeenCalledTimes(1);
    retryNow();
    await vi.advanceTimersByTimeAsync(0);
    expect(read).toHaveBeenCalledTimes(2);
    read.mockImplementation(() => ok('back'));
    window.dispatchEvent(new Event('online'));
    await vi.advanceTimersByTimeAsync(0);
    await expect(done).resolves.toBe('back');
    expect(read).toHaveBeenCalledTimes(3);
    expect(reachStore.getState().unreachable).toBe(false);
  });

  it('says whether the device itself is offline', async () => {
    const onLine = vi.spyOn(navigator, 'onLine', 'get').mockReturnValue(false);
    const read = vi.fn<() => Promise<string>>(failed);
    const done = untilReachable(read, () => 1000);
    await vi.advanceTimersByTimeAsync(0);
    expect(reachStore.getState()).toMatchObject({ unreachable: true, offline: true });
    onLine.mockRestore();
    retryNow();
    await vi.advanceTimersByTimeAsync(0);
    expect(reachStore.getState()).toMatchObject({ unreachable: true, offline: false });
    read.mockImplementation(() => ok('done'));
    retryNow();
    await expect(done).resolves.toBe('done');
  });

  it('passes an answer that is an error through at once: the server did answer', async () => {
    reachStore.setState({ unreachable: true, offline: false, nextTryAt: 1 });
    const read = vi.fn(() => Promise.reject(new Error('the gateway answered HTTP 500')));
    await expect(untilReachable(read, () => 1000)).rejects.toThrow('HTTP 500');
    expect(read).toHaveBeenCalledTimes(1);
    expect(reachStore.getState().unreachable).toBe(false);
  });
});
