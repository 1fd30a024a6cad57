import type { Shift } from './api';

/**
 * The History page's time range: presets in the browser's local time. A shift's window follows
 * the server's rule (gateway/history/shifts.ts): an end not after the start is the next day.
 */

export type RangeChoice =
  | { kind: 'today' }
  | { kind: 'yesterday' }
  | { kind: 'last7' }
  | { kind: 'shift'; date: string; shift: string }
  | { kind: 'custom'; from: string; to: string };

export type Range = { from: number; to: number };

const DAY_MS = 86_400_000;

function midnight(t: number, addDays = 0): number {
  const d = new Date(t);
  return new Date(d.getFullYear(), d.getMonth(), d.getDate() + addDays).getTime();
}

/** `YYYY-MM-DD` naming a real calendar day, as [year, month 1–12, day]; null otherwise. */
export function parseDate(date: string): [number, number, number] | null {
  const m = /^(\d{4})-(\d{2})-(\d{2})$/.exec(date);
  if (!m) return null;
  const [y, mo, d] = [Number(m[1]), Number(m[2]), Number(m[3])];
  const t = new Date(y, mo - 1, d);
  if (t.getFullYear() !== y || t.getMonth() !== mo - 1 || t.getDate() !== d) return null;
  return [y, mo, d];
}

/** The local calendar date of a time (`YYYY-MM-DD`). */
export function localDate(t: number): string {
  const d = new Date(t);
  return `${d.getFullYear()}-${String(d.getMonth() + 1).padStart(2, '0')}-${String(d.getDate()).padStart(2, '0')}`;
}

function hm(s: string): [number, number] {
  const [h, m] = s.split(':').map(Number);
  return [h ?? 0, m ?? 0];
}

/** A shift's [from, to) on a date, local time; null for a date that is not one. */
export function shiftWindow(date: string, shift: Pick<Shift, 'start' | 'end'>): Range | null {
  const d = parseDate(date);
  if (!d) return null;
  const [y, mo, day] = d;
  const [sh, sm] = hm(shift.start);
  const [eh, em] = hm(shift.end);
  const nextDay = eh * 60 + em <= sh * 60 + sm;
  return {
    from: new Date(y, mo - 1, day, sh, sm).getTime(),
    to: new Date(y, mo - 1, day + (nextDay ? 1 : 0), eh, em).getTime(),
  };
}

/** A `datetime-local` value (`2026-03-10T06:00`) as local time; null when it is not one. */
export function parseLocalDateTime(v: string): number | null {
  const m = /^(\d{4})-(\d{2})-(\d{2})T(\d{2}):(\d{2})(?::(\d{2}))?$/.exec(v);
  if (!m) return null;
  const [y, mo, d, h, mi, s] = m.slice(1).map((x) => Number(x ?? 0)) as [
    number,
    number,
    number,
    number,
    number,
    number,
  ];
  const t = new Date(y, mo - 1, d, h, mi, s);
  if (t.getMonth() !== mo - 1 || t.getDate() !== d || t.getHours() !== h) return null;
  return t.getTime();
}

/** The range a choice means at `now`, or why it means none. */
export function resolveRange(
  choice: RangeChoice,
  now: number,
  shifts: readonly Shift[],
): Range | { error: string } {
  switch (choice.kind) {
    case 'today':
      return { from: midnight(now), to: midnight(now, 1) };
    case 'yesterday':
      return { from: midnight(now, -1), to: midnight(now) };
    case 'last7':
      return { from: now - 7 * DAY_MS, to: now };
    case 'shift': {
      const s = shifts.find((x) => x.name === choice.shift);
      if (!s) return { error: 'Pick a shift.' };
      return shiftWindow(choice.date, s) ?? { error: 'Pick a date.' };
    }
    case 'custom': {
      const from = parseLocalDateTime(choice.from);
      const to = parseLocalDateTime(choice.to);
      if (from === null || to === null) return { error: 'Give both a start and an end.' };
      if (from >= to) return { error: 'The start must be before the end.' };
      if (to - from > 400 * DAY_MS) return { error: 'At most 400 days at once.' };
      return { from, to };
    }
  }
}

/** The shift under way at `now` and the date it began on (a night shift began yesterday); null: none. */
export function currentShift(shifts: readonly Shift[], now: number): { date: string; shift: string } | null {
  for (const date of [localDate(now), localDate(midnight(now, -1))])
    for (const s of shifts) {
      const w = shiftWindow(date, s);
      if (w && w.from <= now && now < w.to) return { date, shift: s.name };
    }
  return null;
}
