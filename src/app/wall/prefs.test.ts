// @vitest-environment happy-dom
import { beforeEach, describe, expect, it } from 'vitest';
import type { MachineInfo } from '../../fleet/types';
import { wallColumns } from './alarms';
import {
  groupingFromQuery,
  groupingToQuery,
  loadWallGrouping,
  NO_BAY,
  setWallGrouping,
  WALL_PREFS_KEY,
  wallPrefsStore,
  wallSectionLayout,
  wallSections,
} from './prefs';

const m = (id: string, group?: string): MachineInfo => ({
  id,
  name: id,
  kind: 'xtool',
  simulated: true,
  ...(group ? { group } : {}),
});

describe('the wall grouped by bay', () => {
  beforeEach(() => localStorage.clear());

  it('makes one section per bay, bays by name, fleet order within one, no bay last', () => {
    const sections = wallSections([m('a'), m('b', 'Bay 10'), m('c', 'Bay 2'), m('d', 'Bay 10'), m('e')]);
    expect(sections.map((s) => [s.label, s.machines.map((x) => x.id)])).toEqual([
      ['Bay 2', ['c']],
      ['Bay 10', ['b', 'd']],
      [NO_BAY, ['a', 'e']],
    ]);
    expect(wallSections([m('a')]).map((s) => s.label)).toEqual([NO_BAY]);
  });

  it('reads the grouping from the query, unknown values ignored', () => {
    expect(groupingFromQuery('?group=bay')).toBe('bay');
    expect(groupingFromQuery('?group=none')).toBe('none');
    expect(groupingFromQuery('?group=family')).toBeNull();
    expect(groupingFromQuery('')).toBeNull();
    expect(groupingToQuery('bay')).toBe('?group=bay');
    expect(groupingToQuery('none')).toBe('');
  });

  it('keeps the choice for the browser; anything odd in storage is the default', () => {
    expect(loadWallGrouping()).toBe('none');
    setWallGrouping('bay');
    expect(wallPrefsStore.getState().groupBy).toBe('bay');
    expect(loadWallGrouping()).toBe('bay');
    localStorage.setItem(WALL_PREFS_KEY, '{"groupBy":"family"}');
    expect(loadWallGrouping()).toBe('none');
    localStorage.setItem(WALL_PREFS_KEY, 'not json');
    expect(loadWallGrouping()).toBe('none');
    setWallGrouping('none');
  });

  it('chooses columns that hold the largest cards, small bays side by side', () => {
    // One section, no heading: the one grid's choice (or one more column for a large fleet).
    for (const n of [1, 5, 12, 20]) expect(wallSectionLayout([n], 1.9, 0).columns).toBe(wallColumns(n, 1.9));
    // Five bays of one machine: side by side, three and two (as the one grid), not five flat rows.
    const ones = wallSectionLayout([1, 1, 1, 1, 1], 1.9);
    expect(ones.columns).toBe(3);
    expect(ones.places.map((p) => [p.row, p.column, p.columns, p.rows])).toEqual([
      [1, 1, 1, 1],
      [1, 2, 1, 1],
      [1, 3, 1, 1],
      [3, 1, 1, 1],
      [3, 2, 1, 1],
    ]);
    expect(ones.rowsTemplate).toBe('auto repeat(1, minmax(0, 1fr)) auto repeat(1, minmax(0, 1fr))');
    // A bay larger than the grid takes whole rows; the next starts under it.
    const mixed = wallSectionLayout([2, 5, 8, 5], 1.9);
    expect(mixed.columns).toBeGreaterThanOrEqual(4);
    expect(mixed.columns).toBeLessThanOrEqual(8);
    for (const p of mixed.places) expect(p.column + p.columns - 1).toBeLessThanOrEqual(mixed.columns);
    // Beside the spotlight (a tall area) fewer columns.
    expect(wallSectionLayout([2, 5, 8, 5], 0.8).columns).toBeLessThan(mixed.columns);
  });
});
