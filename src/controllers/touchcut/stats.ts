import { formatDecimal, formatDuration, formatNumber } from '../../ui/format';
import type { Consumable, ProgramRun, StatsSession, ToolTotals } from './wire';

/** Production statistics maths, pure (shared by the view and the tests); CSV is src/ui/csv.ts. */

// ---------------------------------------------------------------------------------------------
// date ranges: `start-date` inclusive, `end-before-date` exclusive (manual), yyyy-mm-dd

export type RangePreset = 'today' | 'yesterday' | 'last7' | 'lastWeek' | 'thisMonth' | 'lastMonth';

export const RANGE_PRESETS: Array<{ id: RangePreset; label: string }> = [
  { id: 'today', label: 'Today' },
  { id: 'yesterday', label: 'Yesterday' },
  { id: 'last7', label: 'Last 7 days' },
  { id: 'lastWeek', label: 'Last week' },
  { id: 'thisMonth', label: 'This month' },
  { id: 'lastMonth', label: 'Last month' },
];

export function localDate(d: Date): string {
  return `${d.getFullYear()}-${String(d.getMonth() + 1).padStart(2, '0')}-${String(d.getDate()).padStart(2, '0')}`;
}

export function shiftDate(date: string, days: number): string {
  const [y, m, d] = date.split('-').map(Number);
  return localDate(new Date(y ?? 1970, (m ?? 1) - 1, (d ?? 1) + days));
}

export interface DateRange {
  startDate: string;
  endBeforeDate: string;
}

/** `today` is the local calendar date (yyyy-mm-dd). Weeks start on Monday (ISO 8601). */
export function presetRange(p: RangePreset, today: string): DateRange {
  const [y, m, d] = today.split('-').map(Number);
  const date = new Date(y ?? 1970, (m ?? 1) - 1, d ?? 1);
  switch (p) {
    case 'today':
      return { startDate: today, endBeforeDate: shiftDate(today, 1) };
    case 'yesterday':
      return { startDate: shiftDate(today, -1), endBeforeDate: today };
    case 'last7':
      return { startDate: shiftDate(today, -6), endBeforeDate: shiftDate(today, 1) };
    case 'lastWeek': {
      const sinceMonday = (date.getDay() + 6) % 7;
      const thisMonday = shiftDate(today, -sinceMonday);
      return { startDate: shiftDate(thisMonday, -7), endBeforeDate: thisMonday };
    }
    case 'thisMonth':
      return {
        startDate: localDate(new Date(date.getFullYear(), date.getMonth(), 1)),
        endBeforeDate: shiftDate(today, 1),
      };
    case 'lastMonth':
      return {
        startDate: localDate(new Date(date.getFullYear(), date.getMonth() - 1, 1)),
        endBeforeDate: localDate(new Date(date.getFullYear(), date.getMonth(), 1)),
      };
  }
}

// ---------------------------------------------------------------------------------------------
// sessions per user

export const TIME_PARTS = [
  { key: 'productiveTime', label: 'Productive', color: 'var(--ok)' },
  { key: 'unproductiveTime', label: 'Unproductive', color: 'var(--info)' },
  { key: 'errorTime', label: 'Error', color: 'var(--bad)' },
  { key: 'idleTime', label: 'Idle', color: 'var(--muted)' },
] as const;

export interface UserTotals {
  user: string;
  sessions: number;
  activeTime: number;
  errorTime: number;
  idleTime: number;
  xyMovingTime: number;
  productiveTime: number;
  unproductiveTime: number;
  toolOnTime: number;
  /** active minus the stacked parts: shown as "other" so the bar never hides time (never < 0). */
  otherTime: number;
}

export function sessionsByUser(sessions: readonly StatsSession[]): UserTotals[] {
  const by = new Map<string, UserTotals>();
  for (const s of sessions) {
    const user = s.user || '(no user)';
    const t =
      by.get(user) ??
      ({
        user,
        sessions: 0,
        activeTime: 0,
        errorTime: 0,
        idleTime: 0,
        xyMovingTime: 0,
        productiveTime: 0,
        unproductiveTime: 0,
        toolOnTime: 0,
        otherTime: 0,
      } satisfies UserTotals);
    t.sessions++;
    t.activeTime += s.activeTime ?? 0;
    t.errorTime += s.errorTime ?? 0;
    t.idleTime += s.idleTime ?? 0;
    t.xyMovingTime += s.xyMovingTime ?? 0;
    t.productiveTime += s.productiveTime ?? 0;
    t.unproductiveTime += s.unproductiveTime ?? 0;
    t.toolOnTime += s.toolOnTime ?? 0;
    by.set(user, t);
  }
  const out = [...by.values()];
  for (const t of out) {
    t.otherTime = Math.max(
      0,
      t.activeTime - t.productiveTime - t.unproductiveTime - t.errorTime - t.idleTime,
    );
  }
  return out.sort((a, b) => b.activeTime - a.activeTime || a.user.localeCompare(b.user));
}

// ---------------------------------------------------------------------------------------------
// tool totals

export interface ToolSum {
  tool: number | null;
  name: string;
  time: number;
  distance: number;
  starts: number;
  errors: number;
}

/** Sum of the sessions' toolTotals per tool, over the range. */
export function toolTotalsOfSessions(sessions: readonly StatsSession[]): ToolSum[] {
  const by = new Map<string, ToolSum>();
  for (const s of sessions)
    for (const t of s.toolTotals) {
      const key = `${t.tool ?? ''}|${t.name ?? ''}`;
      const sum = by.get(key) ?? {
        tool: t.tool ?? null,
        name: t.name ?? `Tool ${t.tool ?? '?'}`,
        time: 0,
        distance: 0,
        starts: 0,
        errors: 0,
      };
      sum.time += t.time ?? 0;
      sum.distance += t.distance ?? 0;
      sum.starts += t.starts ?? 0;
      sum.errors += t.errors ?? 0;
      by.set(key, sum);
    }
  return [...by.values()].sort((a, b) => (a.tool ?? 0) - (b.tool ?? 0));
}

/** Flattens tool totals with their carriages into rows ("Plasma", "Plasma · carriage 1"). */
export interface TotalsRow {
  key: string;
  tool: string;
  carriage: string;
  time: number;
  distance: number;
  starts: number;
  errors: number;
  lastReset: string;
}

export function totalsRows(list: readonly ToolTotals[]): TotalsRow[] {
  const rows: TotalsRow[] = [];
  list.forEach((t, i) => {
    const tool = t.name || `Tool ${t.tool ?? '?'}`;
    rows.push({
      key: `t${i}`,
      tool,
      carriage: 'all',
      time: t.time ?? 0,
      distance: t.distance ?? 0,
      starts: t.starts ?? 0,
      errors: t.errors ?? 0,
      lastReset: t.lastReset ?? '',
    });
    t.carriages.forEach((c, j) =>
      rows.push({
        key: `t${i}c${j}`,
        tool,
        carriage: String(c.carriage ?? j + 1),
        time: c.time ?? 0,
        distance: c.distance ?? 0,
        starts: c.starts ?? 0,
        errors: c.errors ?? 0,
        lastReset: c.lastReset ?? t.lastReset ?? '',
      }),
    );
  });
  return rows;
}

// ---------------------------------------------------------------------------------------------
// consumables

export interface ConsumableTotal {
  key: string;
  toolName: string;
  consType: string;
  consID: string;
  records: number;
  pierces: number;
  distance: number;
  time: number;
}

/** Totals per consumable (tool + type + id). */
export function consumableTotals(list: readonly Consumable[]): ConsumableTotal[] {
  const by = new Map<string, ConsumableTotal>();
  for (const c of list) {
    const key = `${c.toolName ?? ''}|${c.consType ?? ''}|${c.consID ?? ''}`;
    const t = by.get(key) ?? {
      key,
      toolName: c.toolName ?? '',
      consType: c.consType ?? '',
      consID: c.consID ?? '',
      records: 0,
      pierces: 0,
      distance: 0,
      time: 0,
    };
    t.records++;
    t.pierces += c.pierces ?? 0;
    t.distance += c.distance ?? 0;
    t.time += c.time ?? 0;
    by.set(key, t);
  }
  return [...by.values()].sort(
    (a, b) =>
      a.toolName.localeCompare(b.toolName) ||
      a.consType.localeCompare(b.consType) ||
      a.consID.localeCompare(b.consID),
  );
}

export function programCounts(
  runs: readonly ProgramRun[],
): Array<{ name: string; runs: number; last: string }> {
  const by = new Map<string, { name: string; runs: number; last: string }>();
  for (const r of runs) {
    const name = r.name || '(unnamed)';
    const t = by.get(name) ?? { name, runs: 0, last: '' };
    t.runs++;
    if ((r.startTime ?? '') > t.last) t.last = r.startTime ?? '';
    by.set(name, t);
  }
  return [...by.values()].sort((a, b) => b.runs - a.runs || a.name.localeCompare(b.name));
}

// ---------------------------------------------------------------------------------------------
// formatting

export function hours(seconds: number): string {
  return formatNumber(seconds / 3600, 1);
}

export function duration(seconds: number): string {
  return formatDuration(seconds);
}

/** Length in the answer's unit: mm shown as metres for large values. */
export function length(value: number, units: string | undefined): string {
  const imperial = (units ?? '').toLowerCase().startsWith('imp');
  if (imperial) return value >= 1200 ? formatDecimal(value / 12, 1, 'ft') : formatNumber(value, 1, 'in');
  return value >= 10_000 ? formatDecimal(value / 1000, 1, 'm') : formatNumber(value, 0, 'mm');
}

export function lengthUnit(units: string | undefined): string {
  return (units ?? '').toLowerCase().startsWith('imp') ? 'in' : 'mm';
}
