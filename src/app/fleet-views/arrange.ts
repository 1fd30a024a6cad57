import type { Activity, Alarm, MachineInfo, MachineKind } from '../../fleet/types';
import type { FleetPrefs } from './prefs';

/**
 * Sorting, filtering and grouping of the fleet (pure: the fleet page, the list view and the
 * next/previous machine shortcuts share it).
 */

/** What a machine is doing, as the fleet view sorts and filters it. */
export type StateClass = 'alarm' | 'paused' | 'running' | 'idle' | 'unknown' | 'offline';

/** Most urgent first: the order of "sort by state". */
const STATE_RANK: Record<StateClass, number> = {
  alarm: 0,
  paused: 1,
  running: 2,
  idle: 3,
  unknown: 4,
  offline: 5,
};

export const STATE_CLASS_WORDS: Record<StateClass, string> = {
  alarm: 'In alarm',
  paused: 'Paused',
  running: 'Running',
  idle: 'Idle',
  unknown: 'Unknown',
  offline: 'Offline',
};

/** The fleet summary's reading: in alarm when the activity says so or a critical alarm is not acknowledged. */
export function stateClass(s: { activity: Activity; alarms: readonly Alarm[] }): StateClass {
  if (
    s.activity === 'alarm' ||
    s.activity === 'error' ||
    s.alarms.some((a) => a.severity === 'critical' && !a.acknowledged)
  )
    return 'alarm';
  switch (s.activity) {
    case 'running':
    case 'stopping':
      return 'running';
    case 'paused':
      return 'paused';
    case 'idle':
      return 'idle';
    case 'offline':
      return 'offline';
    default:
      return 'unknown';
  }
}

/** Whether the view's order or filter depends on the machines' live state. */
export function needsState(prefs: Pick<FleetPrefs, 'sort' | 'state'>): boolean {
  return prefs.sort === 'state' || prefs.state !== 'all';
}

export interface FleetGroup {
  /** Stable key ("all", "family:xtool", "group:Bay 2", "group:"). */
  key: string;
  /** Heading; null when not grouped. */
  label: string | null;
  ids: string[];
}

const collator = new Intl.Collator(undefined, { numeric: true, sensitivity: 'base' });

/** Machines without a `group` in the machines file. */
export const NO_GROUP = 'No group';

/**
 * The machines to show, in order and in groups. `stateOf` is read only when the preferences
 * need it (`needsState`). `familyLabel` names a family for sorting and headings.
 */
export function arrangeFleet(
  machines: readonly MachineInfo[],
  prefs: FleetPrefs,
  stateOf: (id: string) => StateClass,
  familyLabel: (kind: MachineKind) => string,
): FleetGroup[] {
  const q = prefs.q.trim().toLowerCase();
  const rows = machines
    .map((info, index) => ({
      info,
      index,
      state: needsState(prefs) ? stateOf(info.id) : ('unknown' as StateClass),
    }))
    .filter(
      (r) =>
        (prefs.family === 'all' || r.info.kind === prefs.family) &&
        (prefs.state === 'all' || r.state === prefs.state) &&
        (!q || r.info.name.toLowerCase().includes(q) || r.info.id.includes(q)),
    );
  type Row = (typeof rows)[number];
  const byFile = (a: Row, b: Row) => a.index - b.index;
  const compare: Record<FleetPrefs['sort'], (a: Row, b: Row) => number> = {
    file: byFile,
    name: (a, b) => collator.compare(a.info.name, b.info.name) || byFile(a, b),
    state: (a, b) => STATE_RANK[a.state] - STATE_RANK[b.state] || byFile(a, b),
    family: (a, b) =>
      collator.compare(familyLabel(a.info.kind), familyLabel(b.info.kind)) ||
      collator.compare(a.info.name, b.info.name) ||
      byFile(a, b),
  };
  rows.sort(compare[prefs.sort]);
  if (prefs.groupBy === 'none') return [{ key: 'all', label: null, ids: rows.map((r) => r.info.id) }];

  const groups = new Map<string, FleetGroup>();
  for (const r of rows) {
    const g =
      prefs.groupBy === 'family'
        ? { key: `family:${r.info.kind}`, label: familyLabel(r.info.kind) }
        : { key: `group:${r.info.group ?? ''}`, label: r.info.group ?? NO_GROUP };
    let group = groups.get(g.key);
    if (!group) {
      group = { ...g, ids: [] };
      groups.set(g.key, group);
    }
    group.ids.push(r.info.id);
  }
  // Groups by name; machines without a group last.
  return [...groups.values()].sort(
    (a, b) =>
      Number(a.key === 'group:') - Number(b.key === 'group:') ||
      collator.compare(a.label ?? '', b.label ?? ''),
  );
}

/** The machines in the order shown (groups one after the other). */
export function flatOrder(groups: readonly FleetGroup[]): string[] {
  return groups.flatMap((g) => g.ids);
}

export function sameGroups(a: readonly FleetGroup[], b: readonly FleetGroup[]): boolean {
  return (
    a.length === b.length &&
    a.every((g, i) => {
      const h = b[i];
      return (
        h !== undefined &&
        g.key === h.key &&
        g.label === h.label &&
        g.ids.length === h.ids.length &&
        g.ids.every((id, j) => id === h.ids[j])
      );
    })
  );
}
