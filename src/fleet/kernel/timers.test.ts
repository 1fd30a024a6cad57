import { afterEach, beforeEach, expect, it, vi } from 'vitest';
import { Liveness } from '../faults';
import { alwaysVisible, Poller } from '../link';
import { Lifecycle } from './lifecycle';

beforeEach(() => {
  vi.useFakeTimers();
  vi.setSystemTime(new Date('2026-11-29T10:00:00.250Z'));
});
afterEach(() => {
  vi.restoreAllMocks();
  vi.useRealTimers();
});

/**
 * A fleet page of five machines as the kernel runs it: each tile polled on the shared grid of the
 * tile pace (2 s), each poll's answer 30 ms later, a liveness window of 4.5 s per machine moved on
 * by each answer. Counts the timers set (setTimeout and setInterval calls) over 10 s.
 */
it('a fleet page of five polled machines sets at most one poll timer per grid moment, not one per machine', async () => {
  const lives: Lifecycle[] = [];
  const pollers: Poller[] = [];
  const silences: string[] = [];
  for (let i = 0; i < 5; i++) {
    const life = new Lifecycle();
    life.start();
    const liveness = new Liveness({
      life,
      now: () => Date.now(),
      windowMs: () => 4500,
      onSilent: () => silences.push(`m${i}`),
    });
    liveness.start();
    const poller = new Poller({
      run: async () => {
        await new Promise<void>((r) => setTimeout(r, 30));
        liveness.heard();
      },
      intervalMs: () => 2000,
      visibility: alwaysVisible,
      aligned: () => true,
    });
    lives.push(life);
    pollers.push(poller);
  }
  pollers.forEach((p) => p.start(0));
  await vi.advanceTimersByTimeAsync(2000); // settled on the grid
  const timeouts = vi.spyOn(globalThis, 'setTimeout');
  const intervals = vi.spyOn(globalThis, 'setInterval');
  await vi.advanceTimersByTimeAsync(10_000);
  const polls = pollers.reduce((n, p) => n + p.started, 0);
  // The request stand-in's own 30 ms timers are not the page's: one per poll.
  const pageTimers = timeouts.mock.calls.filter(([, ms]) => ms !== 30).length + intervals.mock.calls.length;
  expect(silences).toEqual([]);
  expect(polls).toBeGreaterThanOrEqual(5 * 5);
  // Five polls per grid moment share one timer; the liveness deadlines ride on (about one each per window).
  expect(pageTimers).toBeLessThanOrEqual(5 + 5 * 3);
  pollers.forEach((p) => p.stop());
  lives.forEach((l) => l.stop());
});
