import { describe, expect, it } from 'vitest';
import type { Activity, Alarm } from '../fleet/types';
import { shownState, summaryBucket, summaryCounts, SUMMARY_BUCKETS } from './status';

const ACTIVITIES: Activity[] = [
  'offline',
  'idle',
  'running',
  'paused',
  'stopping',
  'error',
  'alarm',
  'unknown',
];
const alarm = (severity: Alarm['severity'], acknowledged = false): Alarm => ({
  id: `a-${severity}`,
  severity,
  message: 'x',
  since: 0,
  acknowledged,
});

describe('shownState: one function decides the displayed state', () => {
  it('without an open critical alarm, the activity as it is', () => {
    for (const a of ACTIVITIES) {
      const s = shownState(a, [alarm('warning'), alarm('critical', true)]);
      expect(s.activity).toBe(a);
      expect(s.was).toBeNull();
    }
    expect(shownState('running', []).words).toBe('Running');
    expect(shownState('running', []).tone).toBe('ok');
  });

  it('an unacknowledged critical alarm overrides the chip: "Alarm · was running", never green', () => {
    const s = shownState('running', [alarm('critical')]);
    expect(s).toEqual({ activity: 'alarm', words: 'Alarm · was running', tone: 'bad', was: 'running' });
    expect(shownState('idle', [alarm('info'), alarm('critical')]).words).toBe('Alarm · was idle');
    expect(shownState('alarm', [alarm('critical')]).words).toBe('Alarm');
    expect(shownState('error', [alarm('critical')]).words).toBe('Alarm · error');
    expect(shownState('offline', [alarm('critical')]).words).toBe('Alarm · offline');
  });

  it("the alarm centre's critical alarm overrides too (a machine this page does not see in alarm)", () => {
    expect(shownState('running', [], true).words).toBe('Alarm · was running');
    expect(shownState('running', [], false).words).toBe('Running');
  });
});

describe('the fleet summary is a partition of the fleet', () => {
  it('every displayed state falls in exactly one bucket', () => {
    for (const a of ACTIVITIES)
      for (const alarms of [[], [alarm('critical')], [alarm('warning')]]) {
        const b = summaryBucket(shownState(a, alarms));
        expect(SUMMARY_BUCKETS).toContain(b);
      }
  });

  it('the counts add up to the number of machines; a running machine in alarm is counted once, in alarm', () => {
    const fleet = [
      shownState('running', []),
      shownState('running', [alarm('critical')]),
      shownState('idle', [alarm('critical')]),
      shownState('idle', []),
      shownState('stopping', []),
      shownState('error', []),
      shownState('unknown', []),
      shownState('offline', []),
      shownState('paused', [alarm('warning')]),
    ];
    const c = summaryCounts(fleet);
    expect(c).toEqual({ running: 2, idle: 1, paused: 1, alarm: 3, offline: 1, unknown: 1 });
    expect(Object.values(c).reduce((n, x) => n + x, 0)).toBe(fleet.length);
  });
});
