import type { Tone } from '../ui';
import type { Activity, LinkState, MachineSnapshot } from '../fleet/types';

export const ACTIVITY_WORDS: Record<Activity, string> = {
  offline: 'Offline',
  idle: 'Idle',
  running: 'Running',
  paused: 'Paused',
  stopping: 'Stopping',
  error: 'Error',
  alarm: 'Alarm',
  unknown: 'Unknown',
};

export const ACTIVITY_TONE: Record<Activity, Tone> = {
  offline: 'muted',
  idle: 'info',
  running: 'ok',
  paused: 'paused',
  stopping: 'warn',
  error: 'bad',
  alarm: 'bad',
  unknown: 'muted',
};

export const LINK_TONE: Record<LinkState, Tone> = {
  connecting: 'muted',
  online: 'ok',
  reconnecting: 'warn',
  'needs-login': 'warn',
  'protocol-error': 'bad',
  offline: 'muted',
};

/** Data older than this is shown as stale. */
export const STALE_MS = 10_000;

/** What a machine's card shows (fleet tile, list row, kiosk, wall): the fields a card re-renders on. */
export function cardFields(x: MachineSnapshot) {
  return {
    link: x.link,
    activity: x.activity,
    activityLabel: x.activityLabel,
    job: x.job,
    alarms: x.alarms,
    problem: x.problem,
  };
}
