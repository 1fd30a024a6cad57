import { afterEach, beforeEach, describe, expect, it, vi } from 'vitest';
import { emptySnapshot, type MachineInfo } from '../fleet/types';

/** A fresh copy of the module each time: "the first screen is up" is once per page. */
const fresh = async () => {
  vi.resetModules();
  return import('./first-screen');
};

describe('first screen', () => {
  beforeEach(() => vi.useFakeTimers());
  afterEach(() => vi.useRealTimers());

  it('afterFirstScreen: runs once the first screen is up and the browser idle, once', async () => {
    const m = await fresh();
    const fn = vi.fn();
    m.afterFirstScreen(fn, 4000);
    await vi.advanceTimersByTimeAsync(3000);
    expect(fn).not.toHaveBeenCalled();
    m.firstScreenShown();
    // No requestIdleCallback here: whenIdle falls back to a timer.
    await vi.advanceTimersByTimeAsync(1500);
    expect(fn).toHaveBeenCalledTimes(1);
    await vi.advanceTimersByTimeAsync(10_000);
    expect(fn).toHaveBeenCalledTimes(1);
  });

  it('afterFirstScreen: a first screen that never comes waits maxWaitMs at most; cancel stops it', async () => {
    const m = await fresh();
    const late = vi.fn();
    const cancelled = vi.fn();
    m.afterFirstScreen(late, 4000);
    const cancel = m.afterFirstScreen(cancelled, 4000);
    cancel();
    await vi.advanceTimersByTimeAsync(3999);
    expect(late).not.toHaveBeenCalled();
    await vi.advanceTimersByTimeAsync(1);
    expect(late).toHaveBeenCalledTimes(1);
    m.firstScreenShown();
    await vi.advanceTimersByTimeAsync(5000);
    expect(late).toHaveBeenCalledTimes(1);
    expect(cancelled).not.toHaveBeenCalled();
  });

  it('readWatch takes a reading as the gateway sends it and leaves anything else out', async () => {
    const m = await fresh();
    const ok = { state: 'paused', job: 'a.nc', progress: 0.3, alarm: null, alarmSeverity: null, ageMs: 10 };
    expect(m.readWatch(ok)).toEqual(ok);
    expect(m.readWatch(undefined)).toBeUndefined();
    expect(m.readWatch({ ...ok, state: 'melting' })).toBeUndefined();
    expect(m.readWatch({ ...ok, job: 42 })).toBeUndefined();
    expect(m.readWatch('running')).toBeUndefined();
  });

  it('cardOf: the reading while the session is silent, the session after its first word', async () => {
    const m = await fresh();
    const info: MachineInfo = {
      id: 'm1',
      name: 'M1',
      kind: 'g2core',
      simulated: false,
      watch: { state: 'running', job: null, progress: 1.7, alarm: 'Door', ageMs: 130_000 },
    };
    const card = m.cardOf(info);
    const silent = emptySnapshot('m1');
    const a = card(silent);
    expect(a).toMatchObject({ activity: 'running', link: 'connecting' });
    expect(a.activityLabel).toBe('Read by the console server 2 min ago · connecting…');
    // Progress is clamped; an alarm without a severity is a warning.
    expect(a.job?.progress).toBe(1);
    expect(a.alarms[0]).toMatchObject({ severity: 'warning', message: 'Door' });
    // The same object each time (cards compare shallowly).
    expect(card(silent)).toBe(a);
    expect(m.activityOf(info, silent)).toBe('running');
    const answered = { ...silent, link: 'online' as const, activity: 'idle' as const, updatedAt: 1 };
    expect(card(answered).activity).toBe('idle');
    expect(m.activityOf(info, answered)).toBe('idle');
    // A machine the server cannot read says so.
    const unread = m.cardOf({
      ...info,
      watch: { state: 'unread', job: null, progress: null, alarm: null, ageMs: 5, unread: 'not JSON' },
    })(silent);
    expect(unread).toMatchObject({ activity: 'unknown', alarms: [] });
    expect(unread.activityLabel).toBe('Not read by the console server: not JSON · connecting…');
    expect(
      m.readWatch({ state: 'unread', job: null, progress: null, alarm: null, ageMs: 5, unread: 'x' }),
    ).toBeDefined();
    // No reading: the session's card, whatever it says.
    expect(m.cardOf({ ...info, watch: undefined })(silent).activity).toBe('unknown');
  });
});
