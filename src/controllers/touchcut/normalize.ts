import type { Activity, Alarm, AlarmSeverity, JobSummary, MachineSnapshot } from '../../fleet/types';
import { progressFraction, type MachineInfoWire, type MsgStatus, type Status } from './wire';

/**
 * Status → normalized snapshot. The manual documents the fields but not their values (its only
 * example says "Idle" everywhere), so states are matched by words and anything else is shown as
 * "unknown (raw …)".
 */

const WORDS: Array<[RegExp, Activity]> = [
  [/e-?stop|emergency|fault|error|alarm|abort/i, 'error'],
  [/paus|hold|suspend/i, 'paused'],
  [/stopping|cancell?ing/i, 'stopping'],
  [/run|cut|busy|auto|cycle|execut|pierc|moving|active|marking/i, 'running'],
  [/idle|ready|stopped|complete|finished|waiting|manual/i, 'idle'],
];

export function activityOf(s: Status): { activity: Activity; label: string } {
  const raw = s.machineState ?? s.programState ?? '';
  let activity: Activity = 'unknown';
  for (const [re, a] of WORDS) {
    if (re.test(raw)) {
      activity = a;
      break;
    }
  }
  if (activity === 'unknown') {
    return { activity, label: raw ? `unknown (raw "${raw}")` : 'unknown (no machineState)' };
  }
  const parts = [s.stateName || raw];
  if (s.programState && s.programState !== s.stateName && s.programState !== raw)
    parts.push(`program ${s.programState}`);
  return { activity, label: parts.join(' · ') };
}

const CRITICAL = /error|fault|collision|e-?stop|emergency|fail|lost|crash|limit/i;
const WARNING = /warn|low|hold|due|check|expired|maintenance|not ready/i;

export function severityOf(m: MsgStatus): AlarmSeverity {
  const t = `${m.key ?? ''} ${m.msg ?? ''}`;
  if (CRITICAL.test(t)) return 'critical';
  if (WARNING.test(t)) return 'warning';
  return 'info';
}

/** `msgStatus` → alarms; a message keeps its `since` while it stays. */
export function alarmsOf(msgs: readonly MsgStatus[], prev: readonly Alarm[], now: number): Alarm[] {
  const seen = new Set<string>();
  const out: Alarm[] = [];
  for (const m of msgs) {
    const id = `msg:${m.key || m.msg || '?'}`;
    if (seen.has(id)) continue;
    seen.add(id);
    const before = prev.find((a) => a.id === id);
    out.push({
      id,
      severity: severityOf(m),
      message: m.msg || m.key || '(empty message)',
      since: before?.since ?? now,
      clears: 'cleared on the machine',
    });
  }
  return out;
}

export function hasProgram(name: string | undefined): name is string {
  return !!name && !/^no active program$/i.test(name.trim());
}

export interface JobClock {
  name: string | null;
  startedAt: number | null;
  lastProgress: number | null;
}

/** Job summary with elapsed time since we saw the program start (and a linear estimate of the rest). */
export function jobOf(
  s: Status,
  activity: Activity,
  clock: JobClock,
  now: number,
): { job: JobSummary | null; clock: JobClock } {
  if (!hasProgram(s.programName))
    return { job: null, clock: { name: null, startedAt: null, lastProgress: null } };
  const progress = progressFraction(s.programProgress);
  let { startedAt } = clock;
  const restarted =
    clock.name !== s.programName ||
    (progress !== null && clock.lastProgress !== null && progress < clock.lastProgress - 0.05);
  if (restarted) startedAt = activity === 'running' && (progress ?? 0) < 0.02 ? now : null;
  if (startedAt === null && activity === 'running' && (progress ?? 0) < 0.02) startedAt = now;
  const elapsed = startedAt !== null ? Math.max(0, (now - startedAt) / 1000) : null;
  const remaining =
    elapsed !== null && progress !== null && progress > 0.02 && progress < 1
      ? (elapsed * (1 - progress)) / progress
      : progress === 1
        ? 0
        : null;
  return {
    job: {
      name: s.programName,
      progress,
      elapsed,
      remaining: remaining === null ? null : Math.round(remaining),
    },
    clock: { name: s.programName, startedAt, lastProgress: progress },
  };
}

export function positionsOf(s: Status): Record<string, number> {
  const out: Record<string, number> = {};
  const vec = s.actualPos?.vec ?? [];
  ['X', 'Y', 'Z'].forEach((k, i) => {
    const v = vec[i];
    if (v !== undefined) out[k] = v;
  });
  const rot = s.actualPos?.rot ?? [];
  ['A', 'B', 'C'].forEach((k, i) => {
    const v = rot[i];
    if (v !== undefined && v !== 0) out[k] = v;
  });
  return out;
}

export function identityOf(info: MachineInfoWire): string {
  const name = [info.exeName?.replace(/\.exe$/i, ''), info.exeVersion].filter(Boolean).join(' ');
  return [name || info.programName || 'TouchCut', info.licensedTo].filter(Boolean).join(' · ');
}

export function snapshotPatch(
  s: Status,
  prev: MachineSnapshot,
  clock: JobClock,
  now: number,
): { patch: Partial<MachineSnapshot>; clock: JobClock } {
  const { activity, label } = activityOf(s);
  const alarms = alarmsOf(s.msgStatus, prev.alarms, now);
  const critical = alarms.some((a) => a.severity === 'critical');
  const j = jobOf(s, activity, clock, now);
  return {
    patch: {
      activity: critical && activity !== 'error' ? 'alarm' : activity,
      activityLabel: label,
      alarms,
      job: j.job,
      positions: positionsOf(s),
    },
    clock: j.clock,
  };
}
