import type { Tone } from '../ui';
import type { Activity, AlarmSeverity, LinkState, MachineSnapshot } from '../fleet/types';

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

/** What a machine's state chip shows: one reading for tiles, list rows, wall cards, kiosk and machine page. */
export interface ShownState {
  /** The activity the chip stands for ('alarm' while a critical alarm is unacknowledged). */
  activity: Activity;
  /** The words on the chip ("Alarm · was running"). */
  words: string;
  tone: Tone;
  /** The machine's own activity under an alarm that overrides it; null otherwise. */
  was: Activity | null;
}

/** A critical alarm nobody acknowledged yet. */
export function hasOpenCritical(
  alarms: readonly { severity: AlarmSeverity; acknowledged?: boolean }[],
): boolean {
  return alarms.some((a) => a.severity === 'critical' && !a.acknowledged);
}

/**
 * The displayed state of a machine: its activity, unless a critical alarm is not acknowledged
 * (the machine's own, or `openCritical` from the alarm centre's list), which overrides it: a
 * heater fault on a printer that still reports "running" reads "Alarm · was running".
 */
export function shownState(
  activity: Activity,
  alarms: readonly { severity: AlarmSeverity; acknowledged?: boolean }[],
  openCritical = false,
): ShownState {
  if (!openCritical && !hasOpenCritical(alarms))
    return { activity, words: ACTIVITY_WORDS[activity], tone: ACTIVITY_TONE[activity], was: null };
  if (activity === 'alarm') return { activity, words: ACTIVITY_WORDS.alarm, tone: 'bad', was: null };
  // What the machine did before ("was running"), or what it is now when that is no activity.
  const now = activity === 'error' || activity === 'offline' || activity === 'unknown';
  return {
    activity: 'alarm',
    words: `${ACTIVITY_WORDS.alarm} · ${now ? '' : 'was '}${ACTIVITY_WORDS[activity].toLowerCase()}`,
    tone: 'bad',
    was: activity,
  };
}

/** The fleet header's buckets: every machine in exactly one (a partition of the fleet). */
export type SummaryBucket = 'running' | 'idle' | 'paused' | 'alarm' | 'offline' | 'unknown';

export const SUMMARY_BUCKETS: readonly SummaryBucket[] = [
  'running',
  'idle',
  'paused',
  'alarm',
  'offline',
  'unknown',
];

/** The bucket of a displayed state (stopping counts as running; error as in alarm). */
export function summaryBucket(shown: Pick<ShownState, 'activity'>): SummaryBucket {
  switch (shown.activity) {
    case 'running':
    case 'stopping':
      return 'running';
    case 'idle':
      return 'idle';
    case 'paused':
      return 'paused';
    case 'alarm':
    case 'error':
      return 'alarm';
    case 'offline':
      return 'offline';
    default:
      return 'unknown';
  }
}

/** Counts per bucket; they add up to the number of machines. */
export function summaryCounts(shown: readonly Pick<ShownState, 'activity'>[]): Record<SummaryBucket, number> {
  const c: Record<SummaryBucket, number> = {
    running: 0,
    idle: 0,
    paused: 0,
    alarm: 0,
    offline: 0,
    unknown: 0,
  };
  for (const s of shown) c[summaryBucket(s)] += 1;
  return c;
}
