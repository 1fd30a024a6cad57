import { statusText } from '../codes';
import { G2Fail } from '../sim/fail';
import { pruneEndedJobs } from '../sim/job-wire';
import {
  CTRL,
  MAX_REPORT_KEYS,
  lineProblem,
  scalarsOf,
  sendableLine,
  tooLong,
  type JsonObject,
} from './protocol';
import { LinkDown, type DataLine, type Reply, type SerialLink } from './link';

/**
 * Operations and jobs of a serial g2core, streamed by the gateway (issue 19): a job survives a
 * closed tablet because the gateway, not the browser, feeds the board. One operation streams at
 * a time, line by line through the link's flow control; `line` counts the lines the board has
 * answered (taken into its planner). Hold, resume and kill are single-character controls written
 * at once. A watchdog raises the known "stuck in run" state: no report from the board for
 * `watchdogMs` while an operation runs.
 *
 * Nothing is ever re-sent: a reset board, an unplugged cable or a flushed queue ends the
 * operation in error at the line it reached, and operations waiting behind it end too.
 */

export type OpState = 'pend' | 'run' | 'pause' | 'done' | 'error';
export type JobState = 'queued' | 'running' | 'paused' | 'done' | 'killed' | 'error';

interface StatusError {
  code: number;
  description: string;
  additional_description: string;
}

export interface SerialOp {
  id: number;
  optype: 'run' | 'sendfile';
  value: string[] | string | number;
  lines: string[];
  /** Lines written. */
  sent: number;
  /** Lines answered by the board. */
  done: number;
  state: OpState;
  error: StatusError | null;
  r: JsonObject[];
  jobId: number | null;
  /** The board reported motion (stat run/hold/homing…) while this operation streamed. */
  moved: boolean;
  endTimer: unknown;
}

export interface SerialJob {
  id: number;
  name: string;
  lines: string[];
  state: JobState;
  started: number | null;
  finished: number | null;
  operation: number | null;
}

export interface StreamerEvents {
  /** For the gateway's log: the watchdog, a lost job, a reset. */
  event(level: 'info' | 'warn' | 'error', message: string): void;
}

export const MAX_JOB_BYTES = 8 * 1024 * 1024;
const KEEP_FINISHED = 50;

/** stat values in which the machine moves (or holds motion): run, hold, probe, cycle, homing, jog. */
const MOVING = new Set([5, 6, 7, 8, 9, 10]);
const STOPPED = new Set([1, 3, 4]);

/**
 * The error of an operation that ended: the firmware's own code when the board gave one; 11 (no
 * such device) when the board went away, 200 (generic error) when it was reset.
 */
function statusError(code: number, additional: string): StatusError {
  return { code, description: statusText(code), additional_description: additional };
}

export interface StreamerOptions {
  link: SerialLink;
  watchdogMs: number;
  events: StreamerEvents;
  now: () => number;
  setTimeout: (fn: () => void, ms: number) => unknown;
  clearTimeout: (t: unknown) => void;
}

export class Streamer {
  readonly ops = new Map<number, SerialOp>();
  readonly jobs = new Map<number, SerialJob>();
  private queue: number[] = [];
  private opSeq = 0;
  private jobSeq = 0;
  /** The latest machine state the board reported (merged status reports). */
  readonly sr: Record<string, unknown> = {};
  private lastHeard = 0;
  private watchdog: unknown = null;
  private probe: unknown = null;
  private killTimer: unknown = null;
  /** Set when the watchdog fired: the board stays "stuck in run" until a reset or a report. */
  stuck: { since: number; line: number } | null = null;

  constructor(private readonly o: StreamerOptions) {
    o.link.source = (inFlight) => this.nextLine(inFlight);
    o.link.listen({
      message: (m) => {
        this.heard();
        if (m.type === 'sr') this.onSr(m.sr);
        else if (m.type === 'response' && m.r.sr && typeof m.r.sr === 'object' && !Array.isArray(m.r.sr))
          this.onSr(m.r.sr);
        else if (m.type === 'er' && m.status === 207) this.afterKill();
      },
      reset: () => {
        this.stuck = null;
        this.failAll(statusError(200, 'the board reset (new start-up banner); nothing was re-sent'));
        for (const k of Object.keys(this.sr)) delete this.sr[k];
        this.o.events.event('warn', 'the board reset: a new start-up banner came');
      },
      state: (s) => {
        if (s.state !== 'online' && s.state !== 'connecting') {
          this.failAll(
            statusError(11, `the board went away (${this.o.link.downWords()}); nothing will be re-sent`),
          );
          for (const k of Object.keys(this.sr)) delete this.sr[k];
          this.stuck = null;
        }
      },
    });
  }

  /** The operation that streams now (run or pause), or null. */
  current(): SerialOp | null {
    for (const op of this.ops.values()) if (op.state === 'run' || op.state === 'pause') return op;
    return null;
  }

  private heard(): void {
    this.lastHeard = this.o.now();
    if (this.stuck) {
      this.stuck = null;
      this.o.events.event('info', 'the board reports again: watchdog cleared');
    }
    this.armWatchdog();
  }

  /**
   * The watchdog: quiet for half its time while running, the board is asked for a status report
   * (a dwell or a slow move changes nothing a filtered report would carry); quiet for all of it,
   * the board is taken as stuck in run.
   */
  private armWatchdog(): void {
    if (this.watchdog !== null) this.o.clearTimeout(this.watchdog);
    if (this.probe !== null) this.o.clearTimeout(this.probe);
    this.watchdog = null;
    this.probe = null;
    const op = this.current();
    if (!op || op.state !== 'run') return;
    this.probe = this.o.setTimeout(() => {
      this.probe = null;
      if (this.current()?.state === 'run' && !this.stuck && this.o.link.online)
        this.o.link.request('sr', null).catch(() => undefined);
    }, this.o.watchdogMs / 2);
    this.watchdog = this.o.setTimeout(() => {
      this.watchdog = null;
      const cur = this.current();
      if (!cur || cur.state !== 'run' || this.stuck) return;
      this.stuck = { since: this.lastHeard, line: cur.done };
      this.o.events.event(
        'error',
        `the board has sent nothing for ${Math.round(this.o.watchdogMs / 1000)} s while running (line ${cur.done}), not even an answer to a status request: stuck in run? A supervisor can reset the board`,
      );
    }, this.o.watchdogMs);
  }

  private onSr(sr: JsonObject): void {
    const clean = scalarsOf(sr);
    // A board that keeps inventing keys cannot grow the report without bound.
    for (const k of Object.keys(clean))
      if (!(k in this.sr) && Object.keys(this.sr).length >= MAX_REPORT_KEYS) delete clean[k];
    Object.assign(this.sr, clean);
    const stat = typeof this.sr.stat === 'number' ? this.sr.stat : null;
    const op = this.current();
    if (!op || stat === null) return;
    if (MOVING.has(stat)) op.moved = true;
    if (STOPPED.has(stat) && op.moved && op.done === op.lines.length) this.finish(op, null);
    // A G-code error or an alarm mid-job: the board stopped; the rest is not sent.
    if (stat === 2 || stat === 12 || stat === 13)
      this.finish(op, statusError(stat === 2 ? 204 : stat === 12 ? 205 : 206, 'the machine stopped (alarm)'));
  }

  private nextLine(inFlight: number): DataLine | null {
    const op = this.current();
    if (!op || op.state !== 'run' || this.stuck || op.sent >= op.lines.length) return null;
    // The board answers a JSON line at once, ahead of the lines waiting in it: it is sent only
    // when every line before it has been answered, so it cannot pass them, and alone (the link
    // sends nothing after it until it is answered).
    if (inFlight > 0 && op.lines[op.sent]!.startsWith('{')) return null;
    const i = op.sent++;
    if (this.watchdog === null) this.armWatchdog();
    return { line: op.lines[i]!, done: (reply) => this.lineDone(op, i, reply) };
  }

  private lineDone(op: SerialOp, i: number, reply: Reply | Error): void {
    if (op.state !== 'run' && op.state !== 'pause') return;
    if (reply instanceof Error) {
      const why = reply instanceof LinkDown ? reply.message : String(reply);
      this.finish(
        op,
        statusError(
          reply instanceof LinkDown && reply.reset ? 200 : 11,
          `line ${i + 1} got no answer: ${why}; nothing is re-sent`,
        ),
      );
      return;
    }
    if (reply.status !== 0 && reply.status !== 3 && reply.status !== 4) {
      this.finish(op, statusError(reply.status, `line ${i + 1}: ${op.lines[i]!.slice(0, 80)}`));
      return;
    }
    op.done++;
    // Replies of JSON lines, as the design settles it (the first 100: an answer is never a flood).
    if (Object.keys(reply.r).length && op.r.length < 100) op.r.push(reply.r);
    if (op.done === op.lines.length) {
      // Lines without motion (settings, M-codes) end when answered; motion ends when the board stops.
      op.endTimer = this.o.setTimeout(() => {
        op.endTimer = null;
        const stat = this.sr.stat;
        if (!op.moved && !(typeof stat === 'number' && MOVING.has(stat))) this.finish(op, null);
      }, 1000);
    }
  }

  private finish(op: SerialOp, err: StatusError | null): void {
    if (op.state === 'done' || op.state === 'error') return;
    op.state = err ? 'error' : 'done';
    op.error = err;
    if (op.endTimer !== null) this.o.clearTimeout(op.endTimer);
    op.endTimer = null;
    const job = op.jobId !== null ? this.jobs.get(op.jobId) : undefined;
    if (job && (job.state === 'running' || job.state === 'paused')) {
      job.state = err ? (err.code === 207 ? 'killed' : 'error') : 'done';
      job.finished = this.o.now();
      this.o.events.event(
        err ? 'warn' : 'info',
        `job ${job.id} "${job.name}" ${job.state} at line ${op.done} of ${op.lines.length}${err ? `: ${err.additional_description}` : ''}`,
      );
    }
    this.armWatchdog();
    this.startNext();
    this.prune();
  }

  private failAll(err: StatusError): void {
    for (const op of [...this.ops.values()])
      if (op.state === 'run' || op.state === 'pause' || op.state === 'pend') this.finish(op, err);
  }

  private startNext(): void {
    if (this.current()) return;
    const next = [...this.ops.values()].find((o) => o.state === 'pend');
    if (!next) return;
    next.state = 'run';
    this.o.link.pump();
  }

  private prune(): void {
    const ended = [...this.ops.values()].filter((o) => o.state === 'done' || o.state === 'error');
    for (const o of ended.slice(0, -KEEP_FINISHED)) this.ops.delete(o.id);
    pruneEndedJobs(this.jobs, KEEP_FINISHED);
  }

  // ---------------------------------------------------------------------------- commands

  private requireOnline(): void {
    if (!this.o.link.online) throw new LinkDown(this.o.link.downWords());
  }

  private alarmCheck(): void {
    const stat = this.sr.stat;
    if (stat === 2) throw new G2Fail(204, 'clear the alarm first');
    if (stat === 12) throw new G2Fail(205, 'clear the shutdown first');
    if (stat === 13) throw new G2Fail(206, 'PANIC needs a board reset');
    if (this.stuck) throw new G2Fail(106, 'the board is stuck in run: a supervisor must reset it');
  }

  /**
   * The lines as they will be sent (comments dropped), every one checked before anything is
   * accepted: a bad line answers 400 (413 when too long) and nothing is sent.
   */
  static prepareLines(lines: string[]): string[] {
    const out: string[] = [];
    lines.forEach((l, i) => {
      const s = sendableLine(l);
      if (s === null) return;
      const p = lineProblem(s);
      if (p) throw new G2Fail(tooLong(p) ? 107 : 101, `line ${i + 1}: ${p}`);
      out.push(s);
    });
    if (out.length === 0) throw new G2Fail(101, 'no G-code lines to run');
    return out;
  }

  addOperation(value: string[] | string, lines: string[]): SerialOp {
    this.requireOnline();
    this.alarmCheck();
    return this.newOp('run', value, Streamer.prepareLines(lines), null);
  }

  private newOp(
    optype: SerialOp['optype'],
    value: SerialOp['value'],
    lines: string[],
    jobId: number | null,
  ): SerialOp {
    const op: SerialOp = {
      id: ++this.opSeq,
      optype,
      value,
      lines,
      sent: 0,
      done: 0,
      state: 'pend',
      error: null,
      r: [],
      jobId,
      moved: false,
      endTimer: null,
    };
    this.ops.set(op.id, op);
    this.startNext();
    return op;
  }

  pause(op: SerialOp): void {
    this.requireOnline();
    if (op.state !== 'run') throw new G2Fail(106, `operation ${op.id} is ${op.state}`);
    this.o.link.control(CTRL.feedhold);
    op.state = 'pause';
    this.setJob(op, 'paused');
    this.armWatchdog();
  }

  resume(op: SerialOp): void {
    this.requireOnline();
    if (op.state !== 'pause') throw new G2Fail(106, `operation ${op.id} is not held`);
    this.o.link.control(CTRL.cycleStart);
    op.state = 'run';
    this.setJob(op, 'running');
    this.armWatchdog();
    this.o.link.pump();
  }

  /**
   * Kill: on the streaming operation, feedhold + queue flush + job kill (`!`, `%`, ^D) and every
   * operation waiting behind it ends too; a pending operation is only removed.
   */
  kill(op: SerialOp): void {
    if (op.state === 'pend') {
      this.finish(op, statusError(207, 'removed before it ran'));
      return;
    }
    if (op.state !== 'run' && op.state !== 'pause')
      throw new G2Fail(106, `operation ${op.id} is ${op.state}`);
    this.requireOnline();
    this.o.link.control(CTRL.feedhold);
    this.o.link.control(CTRL.flush);
    this.o.link.control(CTRL.kill);
    for (const o of this.ops.values())
      if (o.state === 'pend') {
        o.state = 'error';
        o.error = statusError(207, `flushed with operation ${op.id}`);
      }
    this.finish(op, statusError(207, 'Job killed'));
    // Lines the flush threw away never answer: forget them once the board confirms the kill.
    this.killTimer = this.o.setTimeout(() => this.afterKill(), 2000);
  }

  private afterKill(): void {
    if (this.killTimer !== null) this.o.clearTimeout(this.killTimer);
    this.killTimer = null;
    this.o.link.forgetInFlight('flushed by the kill');
  }

  private setJob(op: SerialOp, state: JobState): void {
    const job = op.jobId !== null ? this.jobs.get(op.jobId) : undefined;
    if (job) job.state = state;
  }

  /** A board reset (^X) for the "stuck in run" state: everything in flight ends, the banner follows. */
  resetBoard(): void {
    this.requireOnlineOrStuck();
    this.failAll(statusError(200, 'the board was reset by a supervisor'));
    this.o.link.control(CTRL.reset);
  }

  private requireOnlineOrStuck(): void {
    if (!this.o.link.online && !this.stuck) throw new LinkDown(this.o.link.downWords());
  }

  // ---------------------------------------------------------------------------- jobs

  addJob(name: string, text: string): SerialJob {
    const lines = Streamer.prepareLines(text.split(/\r?\n/));
    const job: SerialJob = {
      id: ++this.jobSeq,
      name: (name || `job-${this.jobSeq}.nc`).slice(0, 200),
      lines,
      state: 'queued',
      started: null,
      finished: null,
      operation: null,
    };
    this.jobs.set(job.id, job);
    this.queue.push(job.id);
    return job;
  }

  startJob(job: SerialJob): SerialOp {
    if (job.state !== 'queued') throw new G2Fail(106, `job ${job.id} is ${job.state}`);
    this.requireOnline();
    this.alarmCheck();
    if (this.current() || [...this.ops.values()].some((o) => o.state === 'pend'))
      throw new G2Fail(106, 'the machine is busy with another operation');
    this.queue = this.queue.filter((id) => id !== job.id);
    job.state = 'running';
    job.started = this.o.now();
    const op = this.newOp('sendfile', job.id, job.lines, job.id);
    job.operation = op.id;
    this.o.events.event('info', `job ${job.id} "${job.name}" started (${job.lines.length} lines)`);
    return op;
  }

  moveJob(job: SerialJob, position: number): void {
    const i = this.queue.indexOf(job.id);
    if (i < 0) throw new G2Fail(106, `job ${job.id} is not queued`);
    const to = Math.max(0, Math.min(this.queue.length - 1, Math.round(position)));
    this.queue.splice(i, 1);
    this.queue.splice(to, 0, job.id);
  }

  /** A queued job killed: out of the queue, kept in the list as killed. */
  killQueued(job: SerialJob): void {
    this.queue = this.queue.filter((id) => id !== job.id);
    job.state = 'killed';
    job.finished = this.o.now();
  }

  deleteJob(job: SerialJob): void {
    if (job.state === 'running' || job.state === 'paused')
      throw new G2Fail(106, `job ${job.id} is ${job.state}`);
    this.jobs.delete(job.id);
    this.queue = this.queue.filter((id) => id !== job.id);
  }

  position(job: SerialJob): number | null {
    const i = this.queue.indexOf(job.id);
    return i < 0 ? null : i;
  }

  /** The running job first, then the queue in order, then the finished ones (newest first). */
  jobOrder(): SerialJob[] {
    const all = [...this.jobs.values()];
    const running = all.filter((j) => j.state === 'running' || j.state === 'paused');
    const queued = this.queue.map((id) => this.jobs.get(id)).filter((j): j is SerialJob => !!j);
    const ended = all.filter((j) => !running.includes(j) && !queued.includes(j)).reverse();
    return [...running, ...queued, ...ended];
  }

  dispose(): void {
    for (const t of [this.watchdog, this.probe, this.killTimer]) if (t !== null) this.o.clearTimeout(t);
    for (const op of this.ops.values()) if (op.endTimer !== null) this.o.clearTimeout(op.endTimer);
  }
}
