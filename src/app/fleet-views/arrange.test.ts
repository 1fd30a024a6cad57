import { describe, expect, it } from 'vitest';
import type { Alarm, MachineInfo, MachineKind } from '../../fleet/types';
import { arrangeFleet, flatOrder, NO_GROUP, sameGroups, stateClass, type StateClass } from './arrange';
import { stepMachine } from '../shortcuts/order';
import { DEFAULT_PREFS, type FleetPrefs } from './prefs';

const m = (id: string, name: string, kind: MachineKind, group?: string): MachineInfo => ({
  id,
  name,
  kind,
  simulated: false,
  ...(group ? { group } : {}),
});

// The machines file's order.
const FLEET: MachineInfo[] = [
  m('laser-10', 'Laser 10', 'xtool', 'Bay 2'),
  m('router', 'Router', 'g2core', 'Bay 1'),
  m('laser-2', 'Laser 2', 'xtool', 'Bay 2'),
  m('printer', 'printer A', 'duet'),
  m('plasma', 'Plasma', 'touchcut', 'Bay 1'),
];

const STATES: Record<string, StateClass> = {
  'laser-10': 'running',
  router: 'alarm',
  'laser-2': 'idle',
  printer: 'paused',
  plasma: 'offline',
};

const LABELS: Record<MachineKind, string> = {
  touchcut: 'Kinetic TouchCut',
  g2core: 'g2core CNC',
  duet: 'Duet',
  xtool: 'xTool',
  prunt: 'Prunt',
};

function arrange(prefs: Partial<FleetPrefs>) {
  const read: string[] = [];
  const groups = arrangeFleet(
    FLEET,
    { ...DEFAULT_PREFS, ...prefs },
    (id) => {
      read.push(id);
      return STATES[id] ?? 'unknown';
    },
    (k) => LABELS[k],
  );
  return { groups, order: flatOrder(groups), read };
}

describe('arrangeFleet', () => {
  it('keeps the machines file order by default, without reading any state', () => {
    const { groups, order, read } = arrange({});
    expect(order).toEqual(['laser-10', 'router', 'laser-2', 'printer', 'plasma']);
    expect(groups).toHaveLength(1);
    expect(groups[0]?.label).toBeNull();
    expect(read).toEqual([]);
  });

  it('sorts by name (numbers as numbers, any case), by state (alarms first) and by family', () => {
    expect(arrange({ sort: 'name' }).order).toEqual(['laser-2', 'laser-10', 'plasma', 'printer', 'router']);
    expect(arrange({ sort: 'state' }).order).toEqual(['router', 'printer', 'laser-10', 'laser-2', 'plasma']);
    // Family label, then name.
    expect(arrange({ sort: 'family' }).order).toEqual(['printer', 'router', 'plasma', 'laser-2', 'laser-10']);
  });

  it('filters by state, family and part of the name', () => {
    expect(arrange({ state: 'alarm' }).order).toEqual(['router']);
    expect(arrange({ state: 'running' }).order).toEqual(['laser-10']);
    expect(arrange({ family: 'xtool' }).order).toEqual(['laser-10', 'laser-2']);
    expect(arrange({ q: '  LASER 1 ' }).order).toEqual(['laser-10']);
    expect(arrange({ q: 'printer' }).order).toEqual(['printer']);
    expect(arrange({ family: 'xtool', state: 'idle' }).order).toEqual(['laser-2']);
    expect(arrange({ q: 'nothing like it' }).order).toEqual([]);
  });

  it('groups by family and by the machines file group, no group last', () => {
    const byFamily = arrange({ groupBy: 'family', sort: 'name' }).groups;
    expect(byFamily.map((g) => [g.label, g.ids])).toEqual([
      ['Duet', ['printer']],
      ['g2core CNC', ['router']],
      ['Kinetic TouchCut', ['plasma']],
      ['xTool', ['laser-2', 'laser-10']],
    ]);
    const byGroup = arrange({ groupBy: 'group' }).groups;
    expect(byGroup.map((g) => [g.key, g.label, g.ids])).toEqual([
      ['group:Bay 1', 'Bay 1', ['router', 'plasma']],
      ['group:Bay 2', 'Bay 2', ['laser-10', 'laser-2']],
      ['group:', NO_GROUP, ['printer']],
    ]);
    // Sorted within each group; the walk order is group after group.
    expect(arrange({ groupBy: 'group', sort: 'state' }).order).toEqual([
      'router',
      'plasma',
      'laser-10',
      'laser-2',
      'printer',
    ]);
  });

  it('tells equal arrangements from changed ones', () => {
    expect(sameGroups(arrange({}).groups, arrange({}).groups)).toBe(true);
    expect(sameGroups(arrange({}).groups, arrange({ sort: 'name' }).groups)).toBe(false);
    expect(sameGroups(arrange({ groupBy: 'family' }).groups, arrange({ groupBy: 'group' }).groups)).toBe(
      false,
    );
  });
});

describe('stateClass', () => {
  const alarm = (severity: Alarm['severity'], acknowledged = false): Alarm => ({
    id: 'a',
    severity,
    message: 'x',
    since: 0,
    acknowledged,
  });
  it('reads alarms and activity as the fleet summary does', () => {
    expect(stateClass({ activity: 'running', alarms: [] })).toBe('running');
    expect(stateClass({ activity: 'stopping', alarms: [] })).toBe('running');
    expect(stateClass({ activity: 'error', alarms: [] })).toBe('alarm');
    expect(stateClass({ activity: 'idle', alarms: [alarm('critical')] })).toBe('alarm');
    expect(stateClass({ activity: 'idle', alarms: [alarm('critical', true)] })).toBe('idle');
    expect(stateClass({ activity: 'idle', alarms: [alarm('warning')] })).toBe('idle');
    expect(stateClass({ activity: 'unknown', alarms: [] })).toBe('unknown');
    expect(stateClass({ activity: 'offline', alarms: [] })).toBe('offline');
  });
});

describe('stepMachine', () => {
  const order = ['a', 'b', 'c'];
  it('walks forward and back, wrapping round', () => {
    expect(stepMachine(order, 'a', 1)).toBe('b');
    expect(stepMachine(order, 'c', 1)).toBe('a');
    expect(stepMachine(order, 'a', -1)).toBe('c');
    expect(stepMachine(order, 'b', -1)).toBe('a');
  });
  it('starts at an end for a machine not in the order, and has nothing in an empty one', () => {
    expect(stepMachine(order, 'x', 1)).toBe('a');
    expect(stepMachine(order, 'x', -1)).toBe('c');
    expect(stepMachine([], 'a', 1)).toBeNull();
  });
});
