import { afterEach, beforeEach, describe, expect, it, vi } from 'vitest';
import { currentShift, localDate, parseLocalDateTime, resolveRange, shiftWindow } from './range';

const SHIFTS = [
  { name: 'Early', start: '06:00', end: '14:00' },
  { name: 'Night', start: '22:00', end: '06:00' },
  { name: 'All day', start: '07:00', end: '07:00' },
];

describe('range presets', () => {
  beforeEach(() => {
    vi.useFakeTimers();
    vi.setSystemTime(new Date(2026, 2, 10, 15, 30));
  });
  afterEach(() => vi.useRealTimers());

  it('today and yesterday are whole local days; last 7 days ends now', () => {
    const now = Date.now();
    expect(resolveRange({ kind: 'today' }, now, SHIFTS)).toEqual({
      from: new Date(2026, 2, 10).getTime(),
      to: new Date(2026, 2, 11).getTime(),
    });
    expect(resolveRange({ kind: 'yesterday' }, now, SHIFTS)).toEqual({
      from: new Date(2026, 2, 9).getTime(),
      to: new Date(2026, 2, 10).getTime(),
    });
    expect(resolveRange({ kind: 'last7' }, now, SHIFTS)).toEqual({ from: now - 7 * 86_400_000, to: now });
    expect(localDate(now)).toBe('2026-03-10');
  });

  it('a night shift crosses midnight: 22:00 on the date to 06:00 the next day', () => {
    expect(resolveRange({ kind: 'shift', date: '2026-03-10', shift: 'Night' }, Date.now(), SHIFTS)).toEqual({
      from: new Date(2026, 2, 10, 22, 0).getTime(),
      to: new Date(2026, 2, 11, 6, 0).getTime(),
    });
    // The last night of a month ends in the next month.
    expect(shiftWindow('2026-03-31', SHIFTS[1]!)).toEqual({
      from: new Date(2026, 2, 31, 22).getTime(),
      to: new Date(2026, 3, 1, 6).getTime(),
    });
  });

  it('a day shift stays on its date; an end equal to the start is 24 hours', () => {
    expect(shiftWindow('2026-03-10', SHIFTS[0]!)).toEqual({
      from: new Date(2026, 2, 10, 6).getTime(),
      to: new Date(2026, 2, 10, 14).getTime(),
    });
    expect(shiftWindow('2026-03-10', SHIFTS[2]!)).toEqual({
      from: new Date(2026, 2, 10, 7).getTime(),
      to: new Date(2026, 2, 11, 7).getTime(),
    });
  });

  it('refuses what means no range, in words', () => {
    const now = Date.now();
    expect(resolveRange({ kind: 'shift', date: '2026-02-30', shift: 'Night' }, now, SHIFTS)).toEqual({
      error: 'Pick a date.',
    });
    expect(resolveRange({ kind: 'shift', date: '2026-03-10', shift: 'Gone' }, now, SHIFTS)).toEqual({
      error: 'Pick a shift.',
    });
    expect(
      resolveRange({ kind: 'custom', from: '2026-03-10T10:00', to: '2026-03-10T09:00' }, now, SHIFTS),
    ).toEqual({
      error: 'The start must be before the end.',
    });
    expect(resolveRange({ kind: 'custom', from: '', to: '2026-03-10T09:00' }, now, SHIFTS)).toHaveProperty(
      'error',
    );
    expect(
      resolveRange({ kind: 'custom', from: '2024-01-01T00:00', to: '2026-03-10T09:00' }, now, SHIFTS),
    ).toHaveProperty('error');
  });

  it('custom: datetime-local values are local times', () => {
    expect(parseLocalDateTime('2026-03-10T06:15')).toBe(new Date(2026, 2, 10, 6, 15).getTime());
    expect(parseLocalDateTime('2026-13-10T06:15')).toBeNull();
    expect(
      resolveRange({ kind: 'custom', from: '2026-03-10T06:00', to: '2026-03-10T14:00' }, Date.now(), SHIFTS),
    ).toEqual({
      from: new Date(2026, 2, 10, 6).getTime(),
      to: new Date(2026, 2, 10, 14).getTime(),
    });
  });

  it('the shift under way: a night shift after midnight began yesterday', () => {
    const day = SHIFTS.slice(0, 2);
    expect(currentShift(day, new Date(2026, 2, 10, 7).getTime())).toEqual({
      date: '2026-03-10',
      shift: 'Early',
    });
    expect(currentShift(day, new Date(2026, 2, 10, 23).getTime())).toEqual({
      date: '2026-03-10',
      shift: 'Night',
    });
    expect(currentShift(day, new Date(2026, 2, 11, 2).getTime())).toEqual({
      date: '2026-03-10',
      shift: 'Night',
    });
    expect(currentShift(day, new Date(2026, 2, 10, 15).getTime())).toBeNull();
    expect(currentShift([], Date.now())).toBeNull();
  });
});
