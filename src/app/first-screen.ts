import { z } from 'zod/mini';
import type { Activity, Alarm, JobSummary, MachineInfo, MachineSnapshot, ServerWatch } from '../fleet/types';
import { whenIdle } from '../fleet/lazy';
import { cardFields } from './status';

/**
 * The fleet page's first screen (issue 16). `GET /api/machines` carries, for each machine, what the
 * console server's own watch last read of it (`watch`: state, job, progress, alarm, and how long
 * ago). A card whose machine's session has no answer yet (its family's code still loading, its
 * first read in flight) shows that, marked as the server's, so the page paints a real fleet
 * before any family's code is there; the family's code then loads when the browser is idle and
 * the session's own data replaces it on its first answer.
 */

const SEVERITIES = ['critical', 'warning', 'info'] as const;

/** One machine's `watch` in the machines list (read per machine: a bad one is dropped alone). */
export const watchSchema: z.ZodMiniType<ServerWatch> = z.object({
  state: z.enum(['running', 'paused', 'idle', 'alarm', 'offline', 'unread']),
  job: z.nullable(z.string()),
  progress: z.nullable(z.number()),
  alarm: z.nullable(z.string()),
  alarmSeverity: z.optional(z.nullable(z.enum(SEVERITIES))),
  ageMs: z.nullable(z.number()),
  unread: z.optional(z.nullable(z.string())),
  record: z.optional(
    z.nullable(
      z.object({
        name: z.nullable(z.string()),
        elapsedMs: z.number().check(z.nonnegative()),
        startSeen: z.boolean(),
        progress: z.nullable(z.number().check(z.gte(0), z.lte(1))),
      }),
    ),
  ),
});

/** The machine's `watch` if it reads as one (anything else: none, the card waits for its session). */
export function readWatch(raw: unknown): ServerWatch | undefined {
  if (raw === undefined) return undefined;
  const p = watchSchema.safeParse(raw);
  return p.success ? p.data : undefined;
}

const ACTIVITY_OF: Record<ServerWatch['state'], Activity> = {
  running: 'running',
  paused: 'paused',
  idle: 'idle',
  alarm: 'alarm',
  offline: 'offline',
  unread: 'unknown',
};

type Card = ReturnType<typeof cardFields>;

/** Words for how old the server's reading was when the list was sent. */
function ageWords(ageMs: number | null): string {
  if (ageMs === null) return '';
  const s = Math.round(ageMs / 1000);
  return s < 2 ? ' just now' : s < 120 ? ` ${s} s ago` : ` ${Math.round(s / 60)} min ago`;
}

const cards = new WeakMap<ServerWatch, Card>();

/** The card a machine's server reading makes (one object per reading: cards compare shallowly). */
function cardOfWatch(w: ServerWatch): Card {
  let c = cards.get(w);
  if (c) return c;
  const job: JobSummary | null =
    w.job === null && w.progress === null
      ? null
      : {
          name: w.job,
          progress: w.progress === null ? null : Math.min(1, Math.max(0, w.progress)),
          elapsed: null,
          remaining: null,
        };
  const alarms: Alarm[] =
    w.alarm === null
      ? []
      : [{ id: 'server-watch', severity: w.alarmSeverity ?? 'warning', message: w.alarm, since: 0 }];
  c = {
    link: 'connecting',
    activity: ACTIVITY_OF[w.state],
    activityLabel:
      w.state === 'unread'
        ? `Not read by the console server: ${w.unread ?? 'its answer cannot be read'} · connecting…`
        : `Read by the console server${ageWords(w.ageMs)} · connecting…`,
    job,
    alarms,
    problem: null,
  };
  cards.set(w, c);
  return c;
}

/** Whether a machine's session has said nothing yet (no answer, no failure). */
export function sessionSilent(s: MachineSnapshot): boolean {
  return s.updatedAt === null && s.link === 'connecting' && s.activity === 'unknown';
}

/**
 * The card of a machine: its session's, or, while the session has said nothing yet, the console
 * server's last reading (when the list carried one).
 */
export function cardOf(info: MachineInfo): (s: MachineSnapshot) => Card {
  return (s) => (info.watch && sessionSilent(s) ? cardOfWatch(info.watch) : cardFields(s));
}

/** A machine's activity for counts (the summary bar): the session's, or the server's first reading. */
export function activityOf(info: MachineInfo, s: MachineSnapshot): Activity {
  return info.watch && sessionSilent(s) ? ACTIVITY_OF[info.watch.state] : s.activity;
}

let shown = false;
const waiting = new Set<() => void>();

/** The fleet page has painted its first screen (its tiles, from the server's readings). */
export function firstScreenShown(): void {
  if (shown) return;
  shown = true;
  for (const fn of waiting) fn();
  waiting.clear();
}

/** Runs `fn` once the fleet page's first screen is up (at once if it is). Returns: cancel. */
export function onFirstScreen(fn: () => void): () => void {
  if (shown) {
    fn();
    return () => undefined;
  }
  waiting.add(fn);
  return () => waiting.delete(fn);
}

/**
 * Runs `fn` when the browser is idle after the first screen (the fleet's tiles, or the machine in
 * view answering), or after `maxWaitMs` at the latest (a page whose first screen never comes, a
 * login page). What a first screen does not need waits for it: the alarm layer, the keyboard
 * shortcuts, the service worker. Returns: cancel.
 */
export function afterFirstScreen(fn: () => void, maxWaitMs = 4000): () => void {
  let done = false;
  let cancelIdle: (() => void) | null = null;
  const run = (): void => {
    if (done) return;
    done = true;
    cancel();
    clearTimeout(timer);
    fn();
  };
  const cancel = onFirstScreen(() => {
    cancelIdle = whenIdle(run);
  });
  const timer = setTimeout(run, maxWaitMs);
  return () => {
    done = true;
    cancel();
    cancelIdle?.();
    clearTimeout(timer);
  };
}
