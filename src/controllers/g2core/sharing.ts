import {
  type SharingHints,
  type WatchDecl,
  type WatchNews,
  type WatchSummary,
  watchAlarmsOf,
  watchStateOf,
} from '../../fleet/contract';
import { g2coreAccess } from './access';
import { activityOf, alarmsOf, jobSummary, num } from './model';
import { errorBody, jobListResponse, statusReportResponse } from './wire';

/**
 * How the gateway shares one g2core controller among every viewer (Node-safe, pure: the gateway
 * and the browser import it through `declaration.ts`). The REST design has no socket: the status
 * reports, the job list and the operations the console polls are answered once per period.
 */

/** `GET /status_report` about 4 times a second (session.ts SR_POLL_MS). */
export const STATUS_REPORT_MS = 250;
/**
 * The job list and operations: polled every second (session.ts SLOW_POLL_MS), and at once when
 * `stat` changes ("a state change must see the job that caused it"). The window is the console's
 * own staleness for the job list (queries.ts JOBS_STALE_MS), half the period: a kicked read gets
 * an answer at most that old.
 */
export const JOBS_MS = 500;
export const WATCH_EVERY_MS = 10_000;

/**
 * What the console polls, in exactly the form it sends it (the design's server is still to be
 * written: another spelling is simply not shared):
 * - `GET /status_report` with no query or one `filter` (the changed-only filter holds the values
 *   the browser has, so two browsers share only when they had the same values: the answer is the
 *   same for both). A filter that names a command (`clear`, `alarm`, `shutd`, `panic`) or carries
 *   G-code is a command in access.ts: never shared.
 * - `GET /job`, `GET /operation` and `GET /operation/{id}`, with no query.
 * Not shared: `/version` and the axis modes (once per session run), the settings tree and groups
 * (on demand, and read back after a settings write, which must see the new value), single jobs,
 * and every GET that is a command (`/machine/clear`, `/machine/alarm|shutd|panic`). The gateway
 * must not share a GET that has a body (access.ts: a GET with a body is not a read): it is not
 * the same request as one without.
 */
export function g2coreShareRead(path: string, query: URLSearchParams): number | null {
  const params = [...query];
  let window: number | null = null;
  if (path === '/status_report') {
    const filterOnly = params.length === 1 && params[0]?.[0] === 'filter';
    if (params.length === 0 || filterOnly) window = STATUS_REPORT_MS;
  } else if (params.length === 0 && (path === '/job' || /^\/operation(\/[A-Za-z0-9_-]+)?$/.test(path))) {
    window = JOBS_MS;
  }
  if (window === null) return null;
  const d = g2coreAccess({ method: 'GET', path, query });
  return d.command || d.role !== 'viewer' ? null : window;
}

// ---------------------------------------------------------------------------------- watch

/**
 * `GET /status_report` (no filter: every key the report is configured with, `stat` among them)
 * → the summary, with the console's own reading (model.ts): `stat` to the state, ALARM, SHUTDOWN,
 * PANIC and an open interlock to the alarm in words. The report names no job (`GET /job` does):
 * `job` stays null. A design error body (`{"status":{…}}`), another HTTP status or a report the
 * schema refuses is an error.
 */
export function readStatusReport(status: number, body: string): WatchSummary | Error {
  let json: unknown;
  try {
    json = JSON.parse(body);
  } catch {
    return new Error(`status_report answered ${status}: not JSON (${body.trim().slice(0, 60)})`);
  }
  const err = errorBody.safeParse(json);
  if (status < 200 || status > 299 || err.success) {
    const words = err.success
      ? ` (status ${err.data.status.code}: ${err.data.status.description ?? ''})`
      : '';
    return new Error(`status_report answered ${status}${words}`);
  }
  const p = statusReportResponse.safeParse(json);
  if (!p.success) return new Error('status_report: not a status report');
  const stat = num(p.data['stat']);
  const alarms = alarmsOf(stat, 0, null);
  return {
    state: watchStateOf(activityOf(stat)),
    alarm: alarms.length ? alarms.map((a) => a.message).join('; ') : null,
    job: null,
    alarms: watchAlarmsOf(alarms),
  };
}

/**
 * `GET /job` → the running (or paused) job's name and progress (lines done over lines), the same
 * reading the machine page makes (model.ts `jobSummary`), so the server's job record and the job
 * history name the job as the tile does. Anything else: no news.
 */
export function readJobList(status: number, body: string): WatchNews | null {
  if (status < 200 || status > 299) return null;
  let json: unknown;
  try {
    json = JSON.parse(body);
  } catch {
    return null;
  }
  const p = jobListResponse.safeParse(json);
  if (!p.success) return null;
  const j = jobSummary(p.data, 0);
  return j ? { job: j.name, progress: j.progress } : null;
}

/**
 * The watch: a full status report every 10 s. g2core stops by itself on a limit, an e-stop or a
 * fault (ALARM, SHUTDOWN, PANIC): nothing runs on unattended after it, so the record may come a
 * few seconds later; one small report every 10 s is nothing next to the console's four a second.
 */
export const g2coreWatch: WatchDecl = {
  everyMs: WATCH_EVERY_MS,
  poll: { path: '/status_report', read: readStatusReport },
  // The report names no job: while one runs, the job list names it (and says how far it is).
  jobPoll: { path: '/job', read: readJobList },
};

export const g2coreSharing: SharingHints = {
  shareRead: g2coreShareRead,
  /**
   * The design speaks HTTP/1.1 (its examples), whose connections persist unless a side says
   * otherwise; a status report four times a second should not open a connection each time.
   */
  keepAlive: true,
  /**
   * Behind the REST server is one serial line to the firmware, which answers one JSON line at a
   * time: two lets the next read wait at the server rather than in the gateway, more only queue.
   */
  maxConcurrentReads: 2,
  watch: g2coreWatch,
};
