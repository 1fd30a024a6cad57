import type { Alarm } from '../../fleet/types';
import type { AlarmRecord } from '../alarms/feed';

/**
 * Whether a machine is "in alarm" for the wall screen: a critical or warning alarm not yet
 * acknowledged. Read from the machine's snapshot for now; the one place to change when the wall
 * reads the server's alarm list (`GET /api/alarms`) instead.
 */
export function inAlarmForWall(alarms: readonly Alarm[]): boolean {
  return alarms.some((a) => (a.severity === 'critical' || a.severity === 'warning') && !a.acknowledged);
}

/** What the wall shows of a machine in alarm from the alarm centre's list. */
export interface WallAlarm {
  severity: 'critical' | 'warning';
  message: string;
  since: number;
}

/**
 * The machines in alarm by the alarm centre's list (the console's server, which also sees what
 * no page watches, e.g. a machine gone offline during a job): its most severe active,
 * unacknowledged critical or warning record each.
 */
export function serverAlarmsForWall(records: readonly AlarmRecord[] | null): Map<string, WallAlarm> {
  const out = new Map<string, WallAlarm>();
  for (const r of records ?? []) {
    if (r.clearedAt !== null || r.ackAt !== null || r.severity === 'info') continue;
    const had = out.get(r.machine);
    if (had && (had.severity === 'critical' || r.severity === 'warning')) continue;
    out.set(r.machine, { severity: r.severity, message: r.text, since: r.since });
  }
  return out;
}

/** How long the wall shows each machine in alarm before the next (ms). */
export const SPOTLIGHT_MS = 8000;

/**
 * The machine the wall shows next: the one after `current` among those in alarm (in fleet
 * order, wrapping round), the first when `current` is none of them, null when none is in alarm.
 */
export function nextSpotlight(inAlarm: readonly string[], current: string | null): string | null {
  if (inAlarm.length === 0) return null;
  const i = current === null ? -1 : inAlarm.indexOf(current);
  return inAlarm[(i + 1) % inAlarm.length] ?? null;
}

/** The machine the wall shows now: `current` while it is still in alarm, else the first in alarm. */
export function spotlightNow(inAlarm: readonly string[], current: string | null): string | null {
  if (current !== null && inAlarm.includes(current)) return current;
  return inAlarm[0] ?? null;
}

/** Columns for `n` cards on an area `aspect` (width / height) times as wide as high, cards about 1.5:1. */
export function wallColumns(n: number, aspect: number): number {
  if (n <= 1) return 1;
  return Math.min(n, Math.max(1, Math.round(Math.sqrt((n * aspect) / 1.5))));
}
