import { describe, expect, it } from 'vitest';
import { othersLine, splitForBanner, type Blocking } from './AlarmBanner';

const b = (machineId: string, machineName: string, blocking = false): Blocking => ({
  machineId,
  machineName,
  key: `${machineId}-k`,
  message: `${machineName} fault`,
  since: 0,
  blocking,
  recordId: null,
});

const ALL = [b('router', 'Router'), b('plasma', 'Plasma'), b('p3', 'Printer 3'), b('laser', 'Laser', true)];

describe('the critical banner', () => {
  it("a kiosk shows its own machine's alarms in full and counts every other one, blocking included", () => {
    const { full, others } = splitForBanner(ALL, 'router', true);
    expect(full.map((x) => x.machineId)).toEqual(['router']);
    expect(others.map((x) => x.machineId)).toEqual(['plasma', 'p3', 'laser']);
    expect(othersLine(others, true)).toBe('3 other alarms in the shop');
    expect(othersLine(others.slice(0, 1), true)).toBe('1 other alarm in the shop');
  });

  it('other pages: one line naming the machines; blocking alarms are the modal’s', () => {
    const { full, others } = splitForBanner(ALL, null, false);
    expect(full).toEqual([]);
    expect(othersLine(others, false)).toBe('3 critical — Router, Plasma, Printer 3');
    expect(othersLine(others.slice(1, 2), false)).toBe('Critical — Plasma: Plasma fault');
  });

  it("a machine's page shows its own alarm in full (to acknowledge there), the others as the line", () => {
    const { full, others } = splitForBanner(ALL, 'plasma', false);
    expect(full.map((x) => x.machineId)).toEqual(['plasma']);
    expect(others.map((x) => x.machineId)).toEqual(['router', 'p3']);
  });
});
