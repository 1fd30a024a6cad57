import { dateTimeFormat, numberFormat, relativeTimeFormat } from './locale';

/**
 * Formatting helpers: one way of writing numbers, durations and times across the console, all
 * through the locale policy (`./locale`): the browser's language and time zone unless set.
 * Units are SI symbols after a space (`12.5 mm`, `3 min 05 s`, `1.5 KiB`).
 */

const twoDigits = () => numberFormat({ minimumIntegerDigits: 2, maximumFractionDigits: 0 });

export function formatDuration(seconds: number | null | undefined): string {
  if (seconds === null || seconds === undefined || !Number.isFinite(seconds)) return '—';
  const s = Math.max(0, Math.round(seconds));
  const h = Math.floor(s / 3600);
  const m = Math.floor((s % 3600) / 60);
  const sec = s % 60;
  const whole = numberFormat({ maximumFractionDigits: 0 });
  if (h > 0) return `${whole.format(h)} h ${twoDigits().format(m)} min`;
  if (m > 0) return `${whole.format(m)} min ${twoDigits().format(sec)} s`;
  return `${whole.format(sec)} s`;
}

/** Exactly `digits` decimals. */
export function formatNumber(n: number | null | undefined, digits = 1, unit?: string): string {
  if (n === null || n === undefined || !Number.isFinite(n)) return '—';
  const t = numberFormat({ minimumFractionDigits: digits, maximumFractionDigits: digits }).format(n);
  return unit ? `${t} ${unit}` : t;
}

/** At most `maxDigits` decimals, no trailing zeros (`2`, `2.5`, `2.25`). */
export function formatDecimal(n: number | null | undefined, maxDigits = 2, unit?: string): string {
  if (n === null || n === undefined || !Number.isFinite(n)) return '—';
  const t = numberFormat({ minimumFractionDigits: 0, maximumFractionDigits: maxDigits }).format(n);
  return unit ? `${t} ${unit}` : t;
}

/** A fraction (0.42) as a percentage, written the locale's way (`42%`, `42 %`). */
export function formatPercent(fraction: number | null | undefined, digits = 0): string {
  if (fraction === null || fraction === undefined || !Number.isFinite(fraction)) return '—';
  return numberFormat({
    style: 'percent',
    minimumFractionDigits: digits,
    maximumFractionDigits: digits,
  }).format(fraction);
}

export function formatBytes(n: number | null | undefined): string {
  if (n === null || n === undefined || !Number.isFinite(n)) return '—';
  const units = ['B', 'KiB', 'MiB', 'GiB', 'TiB'];
  let v = n;
  let i = 0;
  while (v >= 1024 && i < units.length - 1) {
    v /= 1024;
    i++;
  }
  const digits = i === 0 ? 0 : 1;
  return `${numberFormat({ minimumFractionDigits: digits, maximumFractionDigits: digits }).format(v)} ${units[i]}`;
}

const TIME: Intl.DateTimeFormatOptions = { hour: '2-digit', minute: '2-digit', second: '2-digit' };
const DATE_TIME: Intl.DateTimeFormatOptions = { year: 'numeric', month: '2-digit', day: '2-digit', ...TIME };

/** Clock time of a ms timestamp, in the policy's time zone (`00:30:00`, `12:30:00 AM`). */
export function formatTime(ms: number | null | undefined): string {
  if (ms === null || ms === undefined || !Number.isFinite(ms)) return '—';
  return dateTimeFormat(TIME).format(ms);
}

/** Date and clock time of a ms timestamp, both in the policy's time zone. */
export function formatDateTime(ms: number | null | undefined): string {
  if (ms === null || ms === undefined || !Number.isFinite(ms)) return '—';
  return dateTimeFormat(DATE_TIME).format(ms);
}

/** "4 sec. ago", "3 min. ago" (in the locale's words). */
export function formatAge(ms: number | null | undefined, now: number): string {
  if (ms === null || ms === undefined || !Number.isFinite(ms)) return 'never';
  const s = Math.max(0, Math.round((now - ms) / 1000));
  const rtf = relativeTimeFormat({ style: 'short', numeric: 'always' });
  // Negated, so in the past: -0 reads "0 sec. ago", where 0 would read "in 0 sec.".
  if (s < 60) return rtf.format(-s, 'second');
  if (s < 3600) return rtf.format(-Math.floor(s / 60), 'minute');
  return rtf.format(-Math.floor(s / 3600), 'hour');
}
