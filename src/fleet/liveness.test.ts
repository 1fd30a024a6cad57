import { afterEach, beforeEach, describe, expect, it, vi } from 'vitest';
import { Liveness } from './faults';
import { Lifecycle } from './kernel/lifecycle';

beforeEach(() => vi.useFakeTimers());
afterEach(() => vi.useRealTimers());

/** A liveness rule on a run, with every timer callback it causes counted. */
function rig(windowMs: () => number) {
  const life = new Lifecycle();
  life.start();
  const silences: number[] = [];
  let wakeUps = 0;
  const once = life.setTimeout.bind(life);
  const every = life.setInterval.bind(life);
  const counted = (fn: () => void) => () => {
    wakeUps++;
    fn();
  };
  life.setTimeout = (fn, ms) => once(counted(fn), ms);
  life.setInterval = (fn, ms) => every(counted(fn), ms);
  const l = new Liveness({ life, now: () => Date.now(), windowMs, onSilent: (q) => silences.push(q) });
  return { life, l, silences, wakeUps: () => wakeUps };
}

describe('Liveness (one timer, issue 34)', () => {
  it('answers every 3 s with a 5 s window: never silent, about one wake-up per answer, not ten a second', async () => {
    const { l, silences, wakeUps, life } = rig(() => 5000);
    l.start();
    for (let i = 0; i < 20; i++) {
      await vi.advanceTimersByTimeAsync(3000);
      l.heard();
    }
    expect(silences).toEqual([]);
    // 60 s: a checking interval of 100 ms would have woken 600 times.
    expect(wakeUps()).toBeLessThanOrEqual(21);
    life.stop();
  });

  it('reports silence once, at the end of the window exactly, and again only after the next answer', async () => {
    const { l, silences, life } = rig(() => 5000);
    l.start();
    await vi.advanceTimersByTimeAsync(2000);
    l.heard();
    await vi.advanceTimersByTimeAsync(4999);
    expect(silences).toEqual([]);
    await vi.advanceTimersByTimeAsync(1);
    expect(silences).toEqual([5000]);
    await vi.advanceTimersByTimeAsync(60_000);
    expect(silences).toHaveLength(1);
    l.heard();
    await vi.advanceTimersByTimeAsync(5000);
    expect(silences).toEqual([5000, 5000]);
    life.stop();
  });

  it('a window that shrank (the slow link ended) is kept from the next answer on, not the old one', async () => {
    let window = 30_000;
    const { l, silences, life } = rig(() => window);
    l.start();
    await vi.advanceTimersByTimeAsync(1000);
    window = 5000;
    l.heard();
    await vi.advanceTimersByTimeAsync(5000);
    expect(silences).toEqual([5000]);
    life.stop();
  });

  it('ends with its run: nothing fires after stop', async () => {
    const { l, silences, life } = rig(() => 5000);
    l.start();
    life.stop();
    await vi.advanceTimersByTimeAsync(60_000);
    expect(silences).toEqual([]);
    expect(life.timerCount).toBe(0);
  });
});
