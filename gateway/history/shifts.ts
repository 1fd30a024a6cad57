import type { Shift } from '../settings';

/**
 * A shift's window on a date, in the server's local time zone. A shift whose end is not after its
 * start ends the next day (a night shift 22:00–06:00 on the 10th runs to 06:00 on the 11th); an
 * end equal to the start is a whole day. Across a daylight-saving change the window is what the
 * clocks say (a night shift is 7 or 9 hours long then).
 */

const DATE = /^(\d{4})-(\d{2})-(\d{2})$/;

/** `YYYY-MM-DD` that names a real calendar day, as [year, month (1–12), day]; null otherwise. */
export function parseDate(date: string): [number, number, number] | null {
  const m = DATE.exec(date);
  if (!m) return null;
  const [y, mo, d] = [Number(m[1]), Number(m[2]), Number(m[3])];
  const t = new Date(y, mo - 1, d);
  if (t.getFullYear() !== y || t.getMonth() !== mo - 1 || t.getDate() !== d) return null;
  return [y, mo, d];
}

function minutes(hhmm: string): [number, number] {
  const [h, m] = hhmm.split(':').map(Number);
  return [h ?? 0, m ?? 0];
}

/** [from, to) in ms since the epoch; null for a date that is not one. */
export function shiftWindow(date: string, shift: Shift): { from: number; to: number } | null {
  const d = parseDate(date);
  if (!d) return null;
  const [y, mo, day] = d;
  const [sh, sm] = minutes(shift.start);
  const [eh, em] = minutes(shift.end);
  const from = new Date(y, mo - 1, day, sh, sm).getTime();
  const nextDay = eh * 60 + em <= sh * 60 + sm;
  const to = new Date(y, mo - 1, day + (nextDay ? 1 : 0), eh, em).getTime();
  return { from, to };
}

/** The local calendar date of a time (`YYYY-MM-DD`). */
export function localDay(t: number): string {
  const d = new Date(t);
  return `${d.getFullYear()}-${String(d.getMonth() + 1).padStart(2, '0')}-${String(d.getDate()).padStart(2, '0')}`;
}

/** `date` plus `days` calendar days (local). */
export function addDays(date: string, days: number): string {
  const d = parseDate(date);
  if (!d) throw new Error(`not a date: ${date}`);
  const [y, mo, day] = d;
  return localDay(new Date(y, mo - 1, day + days).getTime());
}
