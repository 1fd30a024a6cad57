import { afterEach, describe, expect, it, vi } from 'vitest';
import { Lifecycle } from './lifecycle';
import { ManualClock, Scheduler } from './scheduler';

function rig(start = 1_000_000) {
  const clock = new ManualClock(start);
  return { clock, s: new Scheduler(clock) };
}

describe('Scheduler.every: one tick per period', () => {
  it('two subscribers of one period share one timer; both run on each tick; it stops with the last', () => {
    const { clock, s } = rig();
    const a: number[] = [];
    const b: number[] = [];
    const stopA = s.every(1000, () => a.push(clock.now()));
    clock.advance(300);
    const stopB = s.every(1000, () => b.push(clock.now()));
    expect(clock.armed).toBe(1);
    clock.advance(2700);
    expect(a).toEqual([1_001_000, 1_002_000, 1_003_000]);
    // The second subscriber joins the first one's tick (the same moments), not a timer of its own.
    expect(b).toEqual([1_001_000, 1_002_000, 1_003_000]);
    stopA();
    clock.advance(1000);
    expect(a).toHaveLength(3);
    expect(b).toHaveLength(4);
    expect(clock.live).toBe(1);
    stopB();
    expect(clock.live).toBe(0);
    // Another period is another tick.
    const stopC = s.every(500, () => undefined);
    const stopD = s.every(1000, () => undefined);
    expect(clock.armed).toBe(3);
    stopC();
    stopD();
    expect(clock.live).toBe(0);
  });

  it('a subscriber that throws keeps neither the others from running nor its error from being seen', () => {
    const { clock, s } = rig();
    const ran: string[] = [];
    s.every(1000, () => {
      throw new Error('boom');
    });
    s.every(1000, () => ran.push('second'));
    expect(() => clock.advance(1000)).toThrow('boom');
    expect(ran).toEqual(['second']);
  });
});

describe('Scheduler.after', () => {
  it('one-shots due at the same moment share one timer, and each is cancelled on its own', () => {
    const { clock, s } = rig();
    const fired: string[] = [];
    s.after(1000, () => fired.push('a'));
    clock.advance(400);
    const cancelB = s.after(600, () => fired.push('b'));
    s.after(600, () => fired.push('c'));
    expect(clock.armed).toBe(1);
    cancelB();
    clock.advance(600);
    expect(fired).toEqual(['a', 'c']);
    expect(clock.live).toBe(0);
  });

  it('a one-shot cancelled by another of its moment, as that one runs, does not run', () => {
    const { clock, s } = rig();
    const fired: string[] = [];
    let cancelB: () => void = () => undefined;
    s.after(1000, () => {
      fired.push('a');
      cancelB();
    });
    cancelB = s.after(1000, () => fired.push('b'));
    const stopTick = s.every(500, () => {
      fired.push('tick');
      stopOther();
    });
    const stopOther = s.every(500, () => fired.push('other'));
    clock.advance(500);
    expect(fired).toEqual(['tick']);
    clock.advance(500);
    expect(fired.sort()).toEqual(['a', 'tick', 'tick']);
    stopTick();
  });

  it('cancel: the last one-shot of a moment cancelled clears its timer, and nothing fires', () => {
    const { clock, s } = rig();
    const fired: string[] = [];
    const cancel = s.after(1000, () => fired.push('a'));
    expect(clock.live).toBe(1);
    cancel();
    cancel();
    expect(clock.live).toBe(0);
    clock.advance(5000);
    expect(fired).toEqual([]);
  });
});

describe('Scheduler.deadline: re-armed on data', () => {
  it('a deadline pushed back by data fires once, at the new time, with no new timer per message', () => {
    const { clock, s } = rig();
    let last = clock.now();
    const fired: number[] = [];
    const d = s.deadline({ due: () => last + 5000, fire: () => fired.push(clock.now()) });
    d.update(true);
    const armedAtStart = clock.armed;
    // A message every 100 ms for 3 s: the moment moves on 30 times.
    for (let i = 0; i < 30; i++) {
      clock.advance(100);
      last = clock.now();
      d.update();
    }
    expect(clock.armed).toBe(armedAtStart);
    clock.advance(4999);
    expect(fired).toEqual([]);
    clock.advance(1);
    expect(fired).toEqual([last + 5000]);
    // Fired once: the moment is past, nothing more until data moves it.
    clock.advance(60_000);
    expect(fired).toHaveLength(1);
    // About one timer for the first moment and one for the rest, not one per message.
    expect(clock.armed).toBeLessThanOrEqual(armedAtStart + 1);
  });

  it('a moment that came nearer sets the timer anew, and fires at the nearer time', () => {
    const { clock, s } = rig();
    let due = clock.now() + 30_000;
    const fired: number[] = [];
    const d = s.deadline({ due: () => due, fire: () => fired.push(clock.now()) });
    d.update();
    clock.advance(1000);
    due = clock.now() + 5000;
    d.update();
    clock.advance(5000);
    expect(fired).toEqual([due]);
    expect(clock.live).toBe(0);
  });

  it('cancel: a cancelled deadline never fires; a null moment cancels too', () => {
    const { clock, s } = rig();
    let due: number | null = clock.now() + 1000;
    const fired: number[] = [];
    const d = s.deadline({ due: () => due, fire: () => fired.push(clock.now()) });
    d.update();
    d.cancel();
    expect(d.armed).toBe(false);
    clock.advance(5000);
    due = clock.now() + 1000;
    d.update();
    due = null;
    d.update();
    clock.advance(5000);
    expect(fired).toEqual([]);
    expect(clock.live).toBe(0);
  });

  it('after firing, the next moment (if ahead) is set again: a ping then its answer deadline', () => {
    const { clock, s } = rig();
    const start = clock.now();
    let next = start + 2000;
    const fired: number[] = [];
    const d = s.deadline({
      due: () => next,
      fire: () => {
        fired.push(clock.now() - start);
        next = fired.length < 2 ? clock.now() + 3000 : clock.now() - 1;
      },
    });
    d.update();
    clock.advance(10_000);
    expect(fired).toEqual([2000, 5000]);
  });
});

describe('the page scheduler on vitest fake timers', () => {
  afterEach(() => vi.useRealTimers());

  it('a lifecycle run on it: intervals of one period share one timer, all cleared on stop', () => {
    vi.useFakeTimers();
    const s = new Scheduler();
    const life = new Lifecycle(s);
    life.start();
    const ticks: string[] = [];
    life.setInterval(() => ticks.push('a'), 1000);
    life.setInterval(() => ticks.push('b'), 1000);
    expect(vi.getTimerCount()).toBe(1);
    vi.advanceTimersByTime(2000);
    expect(ticks).toEqual(['a', 'b', 'a', 'b']);
    life.stop();
    expect(vi.getTimerCount()).toBe(0);
    expect(s.pending).toBe(0);
  });
});
