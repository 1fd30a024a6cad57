import { describe, expect, it } from 'vitest';
import type { Alarm } from '../../fleet/types';
import type { AlarmRecord } from '../alarms/feed';
import { inAlarmForWall, nextSpotlight, serverAlarmsForWall, spotlightNow, wallColumns } from './alarms';

const alarm = (severity: Alarm['severity'], acknowledged = false): Alarm => ({
  id: `${severity}-${acknowledged}`,
  severity,
  message: 'x',
  since: 0,
  acknowledged,
});

describe('wall screen alarms', () => {
  it('counts critical and warning alarms not acknowledged', () => {
    expect(inAlarmForWall([])).toBe(false);
    expect(inAlarmForWall([alarm('info')])).toBe(false);
    expect(inAlarmForWall([alarm('warning')])).toBe(true);
    expect(inAlarmForWall([alarm('critical')])).toBe(true);
    expect(inAlarmForWall([alarm('critical', true), alarm('warning', true)])).toBe(false);
  });

  it('cycles through the machines in alarm, and keeps one while it is still in alarm', () => {
    expect(nextSpotlight([], 'a')).toBeNull();
    expect(nextSpotlight(['a', 'b', 'c'], null)).toBe('a');
    expect(nextSpotlight(['a', 'b', 'c'], 'a')).toBe('b');
    expect(nextSpotlight(['a', 'b', 'c'], 'c')).toBe('a');
    expect(nextSpotlight(['b', 'c'], 'a')).toBe('b');
    expect(spotlightNow(['a', 'b'], 'b')).toBe('b');
    expect(spotlightNow(['a', 'c'], 'b')).toBe('a');
    expect(spotlightNow([], 'b')).toBeNull();
  });

  it('lays the fleet out to fill a 16:9 screen', () => {
    expect(wallColumns(1, 1.9)).toBe(1);
    expect(wallColumns(5, 1.9)).toBe(3);
    expect(wallColumns(5, 0.8)).toBe(2);
    const cols = wallColumns(100, 1.9);
    expect(cols).toBeGreaterThanOrEqual(10);
    expect(Math.ceil(100 / cols)).toBeLessThanOrEqual(10);
  });
});

describe('serverAlarmsForWall', () => {
  const rec = (id: string, machine: string, over: Partial<AlarmRecord>): AlarmRecord => ({
    id,
    machine,
    machineName: machine,
    family: 'g2core',
    key: `k${id}`,
    severity: 'warning',
    text: `alarm ${id}`,
    blocking: false,
    since: 1,
    clearedAt: null,
    ackBy: null,
    ackAt: null,
    ...over,
  });
  it('keeps each machine’s most severe active, unacknowledged critical or warning record', () => {
    const m = serverAlarmsForWall([
      rec('1', 'a', { severity: 'warning' }),
      rec('2', 'a', { severity: 'critical' }),
      rec('3', 'a', { severity: 'warning' }),
      rec('4', 'b', { severity: 'info' }),
      rec('5', 'c', { severity: 'critical', clearedAt: 5 }),
      rec('6', 'd', { severity: 'critical', ackAt: 5, ackBy: 'olga' }),
      rec('7', 'e', { text: 'went offline during a job' }),
    ]);
    expect([...m.keys()]).toEqual(['a', 'e']);
    expect(m.get('a')?.message).toBe('alarm 2');
    expect(m.get('e')).toEqual({ severity: 'warning', message: 'went offline during a job', since: 1 });
    expect(serverAlarmsForWall(null).size).toBe(0);
  });
});
