import type { WatchAlarm, WatchDecl, WatchJobRecord, WatchNews, WatchSummary } from '../src/fleet/contract';

/**
 * The gateway's own slow watch of every machine (the family's `sharing.watch`), with or without
 * a viewer: one read every `everyMs` (through the same shared path as the browsers' reads, so
 * while someone watches it costs the controller nothing more), and/or the machine's shared
 * stream held open with its frames read. What it learns is a `WatchSummary`; its changes become
 * one log line and one audit entry each (job started, paused, ended; alarm raised and cleared),
 * so the audit log knows when jobs ran even when no screen was open. This is also what alarms
 * and job history build on.
 */

export interface WatchEvent {
  machine: string;
  /** "job started", "job paused", "job resumed", "job ended", "alarm", "alarm cleared" */
  what: string;
  detail: string;
  summary: WatchSummary;
}

export interface WatchHost {
  /** One read of the controller, as the browsers' reads go (held session, secrets, sharing). */
  read(path: string): Promise<{ status: number; body: string; gateway?: boolean }>;
  /**
   * Holds the shared stream at `path` open and hands its frames over; returns the release.
   * `onEnd`: the stream ended (the controller closed it); the watch opens it again later.
   */
  hold?(path: string, onFrame: (frame: string) => void, onEnd: () => void): Promise<() => void>;
  /** A change worth the log and the audit log. */
  report(e: WatchEvent): void;
  /** Every summary learnt, with the one before (the alarm centre reads alarms from it). */
  observe?(prev: WatchSummary, next: WatchSummary): void;
  now?: () => number;
}

const EMPTY: WatchSummary = { state: 'unknown', alarm: null, job: null };

/** What a change of summary means, in the words the audit log keeps (null: nothing worth it). */
export function describeChange(
  prev: WatchSummary,
  next: WatchSummary,
): Array<{ what: string; detail: string }> {
  const out: Array<{ what: string; detail: string }> = [];
  const job = next.job ?? prev.job;
  const named = job ? `: ${job}` : '';
  // The detail says what `what` does not (the job's name, the alarm), never the same word again:
  // the log and the audit page show "job started (a.nc)", not "job started started: a.nc".
  const jobName = job ?? '';
  if (prev.state !== next.state && next.state !== 'unknown') {
    const was = prev.state;
    if (next.state === 'offline' && (was === 'running' || was === 'paused'))
      out.push({ what: 'offline during a job', detail: `was ${was}${named}` });
    else if (next.state === 'offline') out.push({ what: 'offline', detail: '' });
    else if (next.state === 'running' && was === 'paused') out.push({ what: 'job resumed', detail: jobName });
    else if (next.state === 'running') out.push({ what: 'job started', detail: jobName });
    else if (next.state === 'paused') out.push({ what: 'job paused', detail: jobName });
    else if (next.state === 'idle' && (was === 'running' || was === 'paused'))
      out.push({ what: 'job ended', detail: prev.job ?? jobName });
  }
  if (next.alarm && next.alarm !== prev.alarm) out.push({ what: 'alarm', detail: next.alarm });
  else if (!next.alarm && prev.alarm) out.push({ what: 'alarm cleared', detail: prev.alarm });
  if (next.unread && !prev.unread) out.push({ what: 'not read by the server', detail: next.unread });
  else if (!next.unread && prev.unread) out.push({ what: 'read again', detail: `was: ${prev.unread}` });
  return out;
}

/** Polls or stream openings that fail in a row before the watch calls the machine offline. */
export const OFFLINE_AFTER = 2;
/** The first try to open a watched stream again after it ended or failed (ms). */
export const STREAM_RETRY_FIRST_MS = 1000;

/** `current` with the alarms a frame raised added (by key; a frame never clears one). */
function withRaised(current: WatchAlarm[] | undefined, raised: WatchAlarm[]): WatchAlarm[] {
  const byKey = new Map((current ?? []).map((a) => [a.key, a]));
  for (const a of raised) byKey.set(a.key, a);
  return [...byKey.values()];
}

const JOB_STATES: ReadonlySet<WatchSummary['state']> = new Set(['running', 'paused']);
/** States in which no job runs: the record ends, and the next job's start is seen. */
const NO_JOB_STATES: ReadonlySet<WatchSummary['state']> = new Set(['idle', 'alarm']);

/**
 * The job record after a summary (issue 33): a job starts when the machine is first seen running
 * or paused, or when it names another job; it keeps its start and the name once learnt (a later
 * reading that names none keeps it); it ends when the machine is idle or in alarm. While the
 * machine is offline or its state unknown the record stays as it was (nobody knows it ended).
 */
export function nextJobRecord(
  rec: WatchJobRecord | null,
  prev: WatchSummary,
  next: WatchSummary,
  now: number,
): WatchJobRecord | null {
  if (NO_JOB_STATES.has(next.state)) return null;
  if (!JOB_STATES.has(next.state)) return rec;
  const progress =
    typeof next.progress === 'number' && Number.isFinite(next.progress)
      ? Math.min(1, Math.max(0, next.progress))
      : null;
  const named = next.job === null || next.job === '' ? null : next.job;
  if (!rec || (named !== null && rec.name !== null && named !== rec.name))
    return {
      name: named,
      startedAt: now,
      // Seen to start: the machine was known to be without a job, or named another one.
      startSeen: rec !== null || NO_JOB_STATES.has(prev.state),
      progress,
    };
  if (rec.name === (named ?? rec.name) && rec.progress === progress) return rec;
  return { ...rec, name: named ?? rec.name, progress };
}

export class MachineWatch {
  private summary: WatchSummary = EMPTY;
  private timer: ReturnType<typeof setTimeout> | null = null;
  private release: (() => void) | null = null;
  private stopped = false;
  private inFlight = false;
  private failures = 0;
  private streamRetries = 0;
  /** A stream opening in flight, or its retry waiting. */
  private streamPending = false;
  /** When the last good summary came (ms). */
  lastSeen: number | null = null;
  private jobRecord: WatchJobRecord | null = null;
  /** `lookNow` came while a poll was in flight: the next poll follows at once. */
  private again = false;

  constructor(
    readonly machine: string,
    private readonly decl: WatchDecl,
    private readonly host: WatchHost,
  ) {}

  get current(): WatchSummary {
    return this.summary;
  }

  /** The job the machine runs, as the server knows it (null: none): every view's job facts. */
  get job(): WatchJobRecord | null {
    return this.jobRecord;
  }

  start(): void {
    if (this.decl.poll) this.schedule(Math.floor(Math.random() * Math.min(this.decl.everyMs, 2000)));
    this.ensureStream();
  }

  /**
   * Holds the family's stream when it declares one and none is held or on its way. A family may
   * declare it only once it knows the machine's API (a Duet: DSF has the socket, a standalone
   * board none), learned by a poll: checked at start and after every poll.
   */
  private ensureStream(): void {
    if (this.stopped || !this.decl.stream || !this.host.hold || this.release || this.streamPending) return;
    void this.holdStream();
  }

  stop(): void {
    this.stopped = true;
    if (this.timer) clearTimeout(this.timer);
    this.timer = null;
    this.release?.();
    this.release = null;
  }

  /** Applies what was learnt (a poll's summary, or part of one from a frame). */
  learn(news: WatchNews): void {
    const { raise, ...part } = news;
    const prev = this.summary;
    const next: WatchSummary = { ...prev, ...part };
    delete next.raised;
    if (raise?.length) {
      next.alarms = withRaised(part.alarms ?? prev.alarms, raise);
      next.raised = raise.map((a) => a.key);
    }
    this.summary = next;
    const t = (this.host.now ?? Date.now)();
    this.jobRecord = nextJobRecord(this.jobRecord, prev, next, t);
    if (next.state !== 'offline') {
      this.failures = 0;
      this.lastSeen = t;
    }
    // Observed first: the alarm centre makes its record durable (alarms.ts) before the change is
    // announced in the log and the audit log.
    this.host.observe?.(prev, next);
    for (const c of describeChange(prev, next))
      this.host.report({ machine: this.machine, what: c.what, detail: c.detail, summary: next });
  }

  /**
   * The machine did not answer (a poll the gateway could not deliver, a stream that could not be
   * opened): after `OFFLINE_AFTER` in a row it is offline. Its alarms are kept as last known.
   */
  private unreachable(): void {
    this.failures++;
    if (this.failures >= OFFLINE_AFTER && this.summary.state !== 'offline') this.learn({ state: 'offline' });
  }

  /**
   * Reads the machine now instead of at its next turn (a poll already in flight is enough). Used
   * when the server itself changed a simulated machine's world (sim-api.ts), so that a condition
   * cleared and raised again is seen as two, not missed between two polls. A poll in flight may
   * have read the machine before the change: another follows it at once.
   */
  lookNow(): void {
    if (this.stopped || !this.decl.poll) return;
    if (this.inFlight || !this.timer) {
      this.again = true;
      return;
    }
    clearTimeout(this.timer);
    this.schedule(0);
  }

  private schedule(ms: number): void {
    if (this.stopped) return;
    this.timer = setTimeout(() => {
      this.timer = null;
      void this.poll().finally(() => {
        const soon = this.again;
        this.again = false;
        this.schedule(soon ? 0 : this.decl.everyMs);
      });
    }, ms);
  }

  private async poll(): Promise<void> {
    const p = this.decl.poll;
    if (!p || this.inFlight || this.stopped) return;
    this.inFlight = true;
    try {
      let read = p;
      let a = await this.host.read(read.path);
      // The read opened the controller's session and the family learned its API (a Duet probed
      // as standalone): its poll is another one now, read at once with it.
      const now = this.decl.poll;
      if (now && now !== read && !this.stopped) {
        read = now;
        a = await this.host.read(read.path);
      }
      if (this.stopped) return;
      // The gateway's own failure (unreachable, timed out): not the controller's answer.
      if (a.gateway) {
        this.unreachable();
        return;
      }
      const s = read.read(a.status, a.body, this.summary);
      // Answered, but nothing the family reads: "not read by the server", said, never nothing.
      if (s instanceof Error) this.learn({ unread: s.message.slice(0, 300) });
      else this.learn({ ...s, ...(await this.jobNews(s)), unread: null });
    } catch {
      // The read could not be made: the gateway's reachability log says why.
      if (!this.stopped) this.unreachable();
    } finally {
      this.inFlight = false;
      this.ensureStream();
    }
  }

  /**
   * The family's job read (`jobPoll`) when the poll found a job and named none: its name and
   * progress. Nothing when it fails (the summary stands; the record keeps what it had).
   */
  private async jobNews(s: WatchNews): Promise<WatchNews> {
    const jp = this.decl.jobPoll;
    if (!jp || s.job !== null || !s.state || !JOB_STATES.has(s.state) || this.stopped) return {};
    try {
      const a = await this.host.read(jp.path);
      if (a.gateway || this.stopped) return {};
      const news = jp.read(a.status, a.body);
      return news
        ? { job: news.job ?? null, ...(news.progress !== undefined ? { progress: news.progress } : {}) }
        : {};
    } catch {
      return {};
    }
  }

  private async holdStream(): Promise<void> {
    const s = this.decl.stream;
    if (!s || !this.host.hold || this.stopped) {
      this.streamPending = false;
      return;
    }
    this.streamPending = true;
    try {
      const release = await this.host.hold(
        s.path,
        (frame) => {
          const part = s.read(frame);
          if (part) this.learn(part);
        },
        () => {
          this.release = null;
          this.retryStream();
        },
      );
      this.streamPending = false;
      if (this.stopped) release();
      else {
        this.release = release;
        this.streamRetries = 0;
      }
    } catch {
      // Could not open it now. Without a poll, that is how the watch learns the machine is gone.
      if (!this.decl.poll && !this.stopped) this.unreachable();
      this.retryStream();
    }
  }

  /**
   * The stream again: after 1 s the first time (a controller that restarted or dropped its socket
   * is listened to again before its next event, a flame), then every `everyMs`.
   */
  private retryStream(): void {
    this.streamPending = !this.stopped;
    if (this.stopped) return;
    const wait =
      this.streamRetries++ === 0 ? Math.min(STREAM_RETRY_FIRST_MS, this.decl.everyMs) : this.decl.everyMs;
    const t = setTimeout(() => void this.holdStream(), wait);
    t.unref?.();
  }
}
