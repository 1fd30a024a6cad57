import { describe, expect, it } from 'vitest';
import type { Interval, StateSeconds } from './api';
import { hourTicks, layoutStrip, shares } from './layout';

const H = 3_600_000;
const iv = (
  state: Interval['state'],
  from: number,
  to: number,
  open = false,
  alarm: string | null = null,
): Interval => ({
  state,
  alarm,
  from,
  to,
  open,
});

describe('layoutStrip', () => {
  const from = new Date(2026, 2, 10).getTime();
  const to = from + 24 * H;

  it('covers the whole range once: gaps are unrecorded, after now is future, widths add up to 1', () => {
    const now = from + 12 * H;
    const segs = layoutStrip(
      [iv('idle', from + 1 * H, from + 2 * H), iv('running', from + 3 * H, now, true)],
      from,
      to,
      now,
    );
    expect(segs.map((s) => s.kind)).toEqual(['unrecorded', 'idle', 'unrecorded', 'running', 'future']);
    expect(segs.reduce((a, s) => a + s.width, 0)).toBeCloseTo(1, 12);
    for (let i = 1; i < segs.length; i++) expect(segs[i]!.from).toBe(segs[i - 1]!.to);
    expect(segs[0]!.from).toBe(from);
    expect(segs.at(-1)!.to).toBe(to);
    expect(segs[3]).toMatchObject({ left: 3 / 24, width: 9 / 24, open: true });
  });

  it('clips intervals that start before the range or run past now and the range', () => {
    const now = to + 5 * H;
    const segs = layoutStrip(
      [iv('alarm', from - 5 * H, from + 2 * H, false, 'Flame'), iv('running', from + 2 * H, to + 3 * H)],
      from,
      to,
      now,
    );
    expect(segs.map((s) => [s.kind, s.from, s.to])).toEqual([
      ['alarm', from, from + 2 * H],
      ['running', from + 2 * H, to],
    ]);
    expect(segs[0]!.alarm).toBe('Flame');
    expect(segs.reduce((a, s) => a + s.width, 0)).toBeCloseTo(1, 12);
  });

  it('never overlaps: an interval that starts inside the previous one begins where it ended', () => {
    const segs = layoutStrip(
      [iv('running', from, from + 5 * H), iv('paused', from + 4 * H, from + 6 * H)],
      from,
      to,
      to,
    );
    expect(segs.map((s) => [s.kind, s.from, s.to])).toEqual([
      ['running', from, from + 5 * H],
      ['paused', from + 5 * H, from + 6 * H],
      ['unrecorded', from + 6 * H, to],
    ]);
  });

  it('a machine with no record is one unrecorded part; a range in the future is all future', () => {
    expect(layoutStrip([], from, to, to).map((s) => s.kind)).toEqual(['unrecorded']);
    expect(layoutStrip([], from, to, from - H).map((s) => [s.kind, s.width])).toEqual([['future', 1]]);
    expect(layoutStrip([], to, from, to)).toEqual([]);
  });
});

describe('hourTicks', () => {
  it('a day: ticks at whole local hours, at most the count asked', () => {
    const from = new Date(2026, 2, 10, 0, 0).getTime();
    const ticks = hourTicks(from, from + 24 * H, 8);
    expect(ticks.length).toBeLessThanOrEqual(9);
    expect(ticks.map((t) => new Date(t.t).getHours())).toEqual([0, 3, 6, 9, 12, 15, 18, 21, 0]);
    expect(ticks[0]).toMatchObject({ left: 0, day: true });
  });

  it('a night shift from 22:00: ticks after the start, midnight marked as a day', () => {
    const from = new Date(2026, 2, 10, 22, 0).getTime();
    const ticks = hourTicks(from, from + 8 * H, 8);
    expect(ticks.map((t) => new Date(t.t).getHours())).toEqual([22, 23, 0, 1, 2, 3, 4, 5, 6]);
    expect(ticks.filter((t) => t.day).map((t) => new Date(t.t).getDate())).toEqual([11]);
  });

  it('a short range: ticks at whole minutes', () => {
    const from = new Date(2026, 2, 10, 14, 7).getTime();
    const ticks = hourTicks(from, from + 13 * 60_000, 8);
    expect(ticks.map((t) => new Date(t.t).getMinutes())).toEqual([10, 15, 20]);
  });

  it('a week: one tick a day at local midnight', () => {
    const from = new Date(2026, 2, 3, 10, 30).getTime();
    const ticks = hourTicks(from, from + 7 * 24 * H, 8);
    expect(ticks).toHaveLength(7);
    for (const t of ticks) expect(new Date(t.t).getHours()).toBe(0);
  });
});

describe('shares', () => {
  const secs = (p: Partial<StateSeconds>): StateSeconds => ({
    running: 0,
    paused: 0,
    idle: 0,
    alarm: 0,
    offline: 0,
    unknown: 0,
    unrecorded: 0,
    ...p,
  });

  it('fractions of the span and whole percentages that add up to 100', () => {
    const s = shares(secs({ running: 1000, idle: 1000, alarm: 1000 }), 3000);
    expect(s.find((x) => x.key === 'running')?.fraction).toBeCloseTo(1 / 3, 12);
    expect(s.reduce((a, x) => a + x.percent, 0)).toBe(100);
    expect(s.filter((x) => x.percent > 0).map((x) => x.percent)).toEqual([34, 33, 33]);
  });

  it('exact shares stay exact', () => {
    const s = shares(secs({ running: 4500, paused: 900, unrecorded: 3600 }), 9000);
    expect(Object.fromEntries(s.map((x) => [x.key, x.percent]))).toMatchObject({
      running: 50,
      paused: 10,
      unrecorded: 40,
    });
  });

  it('an empty span is all zero', () => {
    expect(shares(secs({}), 0).every((x) => x.percent === 0 && x.fraction === 0)).toBe(true);
  });
});
