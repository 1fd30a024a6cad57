import type { Tone } from '../../ui';
import { ACTIVITY_TONE } from '../status';
import type { HistoryState, Interval, StateSeconds } from './api';

/** Pure layout of the History page's pictures: timeline strips, hour ticks, utilisation shares. */

export type SegmentKind = HistoryState | 'unrecorded' | 'future';

export interface Segment {
  kind: SegmentKind;
  from: number;
  to: number;
  alarm: string | null;
  open: boolean;
  /** Position and width as fractions of the range (0..1); the widths add up to 1. */
  left: number;
  width: number;
}

/** The fleet's tones where a state maps to one (src/app/status.ts). */
export const STATE_TONE: Record<HistoryState, Tone> = {
  running: ACTIVITY_TONE.running,
  paused: ACTIVITY_TONE.paused,
  idle: ACTIVITY_TONE.idle,
  alarm: ACTIVITY_TONE.alarm,
  offline: ACTIVITY_TONE.offline,
  unknown: ACTIVITY_TONE.unknown,
};

export const KIND_WORDS: Record<SegmentKind, string> = {
  running: 'Running',
  paused: 'Paused',
  idle: 'Idle',
  alarm: 'Alarm',
  offline: 'Offline',
  unknown: 'Unknown',
  unrecorded: 'Not recorded',
  future: 'Not yet',
};

/**
 * One machine's strip over [from, to): its intervals clipped to the range and to `now`, the time
 * no interval covers as `unrecorded`, the time after `now` as `future`. Every instant of the range
 * is in exactly one segment.
 */
export function layoutStrip(
  intervals: readonly Interval[],
  from: number,
  to: number,
  now: number,
): Segment[] {
  const span = to - from;
  if (!(span > 0)) return [];
  const end = Math.min(to, Math.max(from, now));
  const out: Segment[] = [];
  const push = (kind: SegmentKind, a: number, b: number, alarm: string | null = null, open = false) => {
    if (b <= a) return;
    out.push({ kind, from: a, to: b, alarm, open, left: (a - from) / span, width: (b - a) / span });
  };
  let cursor = from;
  const sorted = [...intervals].sort((x, y) => x.from - y.from);
  for (const i of sorted) {
    const a = Math.max(i.from, cursor);
    const b = Math.min(i.to, end);
    if (b <= a) continue;
    push('unrecorded', cursor, a);
    push(i.state, a, b, i.alarm, i.open);
    cursor = b;
  }
  push('unrecorded', cursor, end);
  push('future', Math.max(cursor, end), to);
  return out;
}

export interface Tick {
  t: number;
  left: number;
  /** A tick at local midnight (the label names the day). */
  day: boolean;
}

const STEPS_MIN = [5, 10, 15, 30, 60, 120, 180, 240, 360, 720, 1440, 2880, 4320, 10080, 20160, 43200];

/** Ticks at whole local minutes, hours or days inside [from, to], at most `maxTicks`. */
export function hourTicks(from: number, to: number, maxTicks: number): Tick[] {
  const span = to - from;
  if (!(span > 0) || maxTicks < 1) return [];
  const step = STEPS_MIN.find((m) => span / (m * 60_000) <= maxTicks) ?? STEPS_MIN[STEPS_MIN.length - 1]!;
  const start = new Date(from);
  const [y, mo, d] = [start.getFullYear(), start.getMonth(), start.getDate()];
  const out: Tick[] = [];
  // Counted on the local clock from the start's midnight (a tick is what the clock says, across DST).
  const at = (k: number) =>
    step < 1440
      ? new Date(y, mo, d, 0, k * step).getTime()
      : new Date(y, mo, d + (k * step) / 1440).getTime();
  for (let k = 0; k < 5000; k++) {
    const t = at(k);
    if (t > to) break;
    const c = new Date(t);
    if (t >= from) out.push({ t, left: (t - from) / span, day: c.getHours() === 0 && c.getMinutes() === 0 });
  }
  return out;
}

export const SHARE_KEYS = ['running', 'paused', 'idle', 'alarm', 'offline', 'unknown', 'unrecorded'] as const;
export type ShareKey = (typeof SHARE_KEYS)[number];

export interface Share {
  key: ShareKey;
  seconds: number;
  /** seconds / span (0..1). */
  fraction: number;
  /** Whole percentages that add up to 100 (largest remainders), 0 for an empty span. */
  percent: number;
}

/** Each state's share of a span; the whole percentages add up to 100. */
export function shares(seconds: StateSeconds, spanS: number): Share[] {
  const total = spanS > 0 ? spanS : 0;
  const raw = SHARE_KEYS.map((key) => {
    const s = Math.max(0, seconds[key]);
    const fraction = total > 0 ? Math.min(1, s / total) : 0;
    return { key, seconds: s, fraction, exact: fraction * 100 };
  });
  const floors = raw.map((r) => Math.floor(r.exact));
  const sum = raw.reduce((a, r) => a + r.exact, 0);
  let left = total > 0 ? Math.round(sum) - floors.reduce((a, b) => a + b, 0) : 0;
  const order = raw
    .map((r, i) => ({ i, rem: r.exact - Math.floor(r.exact) }))
    .sort((a, b) => b.rem - a.rem || a.i - b.i);
  const percent = [...floors];
  for (const { i } of order) {
    if (left <= 0) break;
    percent[i] = (percent[i] ?? 0) + 1;
    left--;
  }
  return raw.map((r, i) => ({
    key: r.key,
    seconds: r.seconds,
    fraction: r.fraction,
    percent: percent[i] ?? 0,
  }));
}
