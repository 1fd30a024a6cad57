import type { JobCommandIds } from '../../src/fleet/contract';
import type { Retention } from '../settings';

/** The production history's words and shapes: what the recorder (recorder.ts) writes and the queries (reader.ts) answer. */

export const STATES = ['running', 'paused', 'idle', 'alarm', 'offline', 'unknown'] as const;
export type HistoryState = (typeof STATES)[number];
export const OUTCOMES = ['finished', 'cancelled', 'failed', 'unknown'] as const;
export type Outcome = (typeof OUTCOMES)[number];

export type JobCommand = 'start' | 'pause' | 'resume' | 'stop';

/**
 * The console's job commands (the `X-Shopdeck-Command` ids the families send) by what they do,
 * from each family's `jobs` declaration (`FamilyDeclaration.jobs`): its emergency stop also
 * stops the job.
 */
export function jobCommandsOf(
  families: Partial<Record<string, { jobs?: JobCommandIds }>>,
): Readonly<Record<string, JobCommand>> {
  const out: Record<string, JobCommand> = {};
  for (const f of Object.values(families)) {
    const j = f?.jobs;
    if (!j) continue;
    if (j.start) out[j.start] = 'start';
    out[j.pause] = 'pause';
    out[j.resume] = 'resume';
    out[j.stop] = 'stop';
    if (j.estop) out[j.estop] = 'stop';
  }
  return out;
}

export interface HistoryMachine {
  id: string;
  name: string;
  kind: string;
}

export interface JobRow {
  id: number;
  machine: string;
  family: string;
  name: string | null;
  /** ms since the epoch */
  startedAt: number;
  endedAt: number | null;
  /** null: still open */
  outcome: Outcome | null;
  runningMs: number;
  pausedMs: number;
  progress: number | null;
  startedBy: string | null;
  pausedBy: string | null;
  resumedBy: string | null;
  stoppedBy: string | null;
  endAlarm: string | null;
}

export interface Interval {
  machine: string;
  state: HistoryState;
  alarm: string | null;
  /** Clipped to the range asked for. */
  from: number;
  to: number;
  /** Still open (its end is "now"). */
  open: boolean;
}

export type StateSeconds = Record<HistoryState | 'unrecorded', number>;

export interface JobQuery {
  /** The machines the asker may see (null: all). */
  machines: readonly string[] | null;
  machine?: string;
  family?: string;
  outcome?: Outcome | 'open';
  /** Jobs that overlap [from, to). */
  from?: number;
  to?: number;
  /** Text in the job's name or in a user's name (case-insensitive). */
  q?: string;
  limit?: number;
  offset?: number;
}

export interface RangeQuery {
  machines: readonly string[] | null;
  machine?: string;
  from: number;
  to: number;
}

export interface StopReason {
  alarm: string | null;
  count: number;
  ms: number;
  machines: string[];
}

export interface JobCounts {
  finished: number;
  cancelled: number;
  failed: number;
  unknown: number;
  /** Overlapping the range and not ended in it (ended later, or still open). */
  inProgress: number;
}

export interface TouchcutDay {
  machine: string;
  day: string;
  pulledAt: number;
  stats: unknown;
}

export interface HistoryInfo {
  file: string;
  /** The database file with its write-ahead log. */
  sizeBytes: number;
  schemaVersion: number;
  oldest: { job: number | null; state: number | null; touchcutDay: string | null };
  counts: { jobs: number; states: number; touchcutDays: number };
  retention: Retention;
}
