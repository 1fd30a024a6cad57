import { formatDuration, formatPercent } from '../ui/format';
import { useNow } from './react';
import { useJobRecord, type ReceivedJobRecord } from './job-records';
import type { JobSummary } from './types';

/**
 * A machine's job facts, one record for every view (issue 33): the console server's job record
 * (the watch keeps it: name, when it first saw the job, progress), which every page gets with
 * `GET /api/machines` and refreshes, completed by the machine's own live reading only where the
 * server knows nothing. The tile, the list, the wall, the kiosk, each family's machine page and
 * the history write them with `formatJob`: the same name, the same start (kept across page loads:
 * it is the server's), the same percentage (one rounding: down) and the same words for time left.
 */

export type { ReceivedJobRecord };

export interface JobFacts {
  name: string | null;
  /** When the job started (ms, this page's clock); null: unknown. */
  startedAt: number | null;
  /** False: the job is older than `startedAt` (the server found it under way). */
  startSeen: boolean;
  /** 0..1, null when unknown. */
  progress: number | null;
  /** Seconds left, and whether the machine said it or the console estimated it from pace. */
  remaining: { seconds: number; how: 'machine' | 'estimate' } | null;
}

/** Below this much progress a pace says nothing yet about the rest. */
const ESTIMATE_FROM = 0.01;

/**
 * The facts of a machine's job: the server's record first (name, start, progress), the machine's
 * live reading (`live`, the session's) only for what the record does not know. Time left is the
 * pace so far (elapsed over progress) when the start is known and progress is past 1 %, else the
 * machine's own figure if it gives one, else unknown: never invented.
 */
export function jobFactsOf(
  live: JobSummary | null,
  server: ReceivedJobRecord | null,
  now: number,
): JobFacts | null {
  const rec = server?.record ?? null;
  if (!rec && !live) return null;
  const name = rec?.name ?? live?.name ?? null;
  const p = rec?.progress ?? live?.progress ?? null;
  const progress = p === null || !Number.isFinite(p) ? null : Math.min(1, Math.max(0, p));
  const startedAt =
    rec && server
      ? server.receivedAt - rec.elapsedMs
      : live?.elapsed !== null && live?.elapsed !== undefined && Number.isFinite(live.elapsed)
        ? now - live.elapsed * 1000
        : null;
  const startSeen = rec ? rec.startSeen : startedAt !== null;
  let remaining: JobFacts['remaining'] = null;
  if (progress === 1) remaining = { seconds: 0, how: 'machine' };
  // Without a server record, the machine's own figure comes first (it is this page's only source).
  else if (
    !rec &&
    live?.remaining !== null &&
    live?.remaining !== undefined &&
    Number.isFinite(live.remaining)
  )
    remaining = { seconds: Math.max(0, live.remaining), how: 'machine' };
  else if (startedAt !== null && startSeen && progress !== null && progress >= ESTIMATE_FROM) {
    const elapsed = Math.max(0, now - startedAt) / 1000;
    remaining = { seconds: Math.round((elapsed * (1 - progress)) / progress), how: 'estimate' };
  } else if (live?.remaining !== null && live?.remaining !== undefined && Number.isFinite(live.remaining))
    remaining = { seconds: Math.max(0, live.remaining), how: 'machine' };
  return { name, startedAt, startSeen, progress, remaining };
}

/** The words every view shows for a job. */
export interface JobWords {
  name: string;
  /** "running for 12 min 05 s", "running for at least 3 min 10 s", "running time unknown". */
  runningFor: string;
  /** "16%" (rounded down: 16.9 % is not 17 % done), "progress unknown". */
  percent: string;
  /** The fraction the bar shows (the same one the percentage is made of). */
  fraction: number | null;
  /** "4 min 10 s left", "about 4 min 10 s left (estimate)", "remaining: cannot estimate". */
  remaining: string;
  /** The same split for a big figure: "4 min 10 s" / "—", and what it is: "left", "left (estimate)", "remaining: cannot estimate". */
  remainingFigure: string;
  remainingNote: string;
}

/** A job with no name the server or the machine knows. */
export const UNNAMED_JOB = 'Unnamed job';

/** The one rounding of progress: down to a whole percent. */
export function floorPercent(fraction: number): number {
  return Math.floor(Math.min(1, Math.max(0, fraction)) * 100 + 1e-9) / 100;
}

export function formatJob(f: JobFacts, now: number): JobWords {
  const ran = f.startedAt === null ? null : Math.max(0, now - f.startedAt) / 1000;
  return {
    name: f.name ?? UNNAMED_JOB,
    runningFor:
      ran === null
        ? 'running time unknown'
        : `running for ${f.startSeen ? '' : 'at least '}${formatDuration(ran)}`,
    percent: f.progress === null ? 'progress unknown' : formatPercent(floorPercent(f.progress)),
    fraction: f.progress === null ? null : floorPercent(f.progress),
    remainingFigure: f.remaining === null ? '—' : formatDuration(f.remaining.seconds),
    remainingNote:
      f.remaining === null
        ? 'remaining: cannot estimate'
        : f.remaining.how === 'estimate'
          ? 'left (estimate)'
          : 'left',
    remaining:
      f.remaining === null
        ? 'remaining: cannot estimate'
        : f.remaining.how === 'estimate'
          ? `about ${formatDuration(f.remaining.seconds)} left (estimate)`
          : `${formatDuration(f.remaining.seconds)} left`,
  };
}

/**
 * A machine's job in the words every view shows, from its server record and its session's live
 * reading (`live`); null: no job. Re-renders each second (the running time) and on each refresh.
 */
export function useJobWords(id: string, live: JobSummary | null): JobWords | null {
  const server = useJobRecord(id);
  const now = useNow(1000);
  const facts = jobFactsOf(live, server, now);
  return facts ? formatJob(facts, now) : null;
}
