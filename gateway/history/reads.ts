import type { ServerResponse } from 'node:http';
import { Worker } from 'node:worker_threads';
import { sendJson, sendJsonText } from '../http-util';
import type { Logger } from '../log';
import type { FromWorker, ReadJob, ToWorker } from './read-protocol';

/**
 * The history's reads, off the gateway's thread: a pool of read workers (read-worker.ts, each
 * with read-only connections of its own), and the bounds on what waits for them.
 *
 * - `WORKERS` workers, started at the first question, kept until the history closes; one that
 *   dies fails its questions (500) and is replaced at the next.
 * - Per asker (the user; in open mode the address): at most `PER_USER_EXPORTS` exports (`.csv`)
 *   and `PER_USER` questions at once; beyond, 429 with `Retry-After`.
 * - Overall: `RUNNING` questions in the workers at once, `QUEUE` more waiting (first come first
 *   served), each at most `QUEUE_WAIT_MS`; beyond, 503 with `Retry-After`.
 * - An export is written as it is read, with backpressure (at most 2 chunks of 64 KiB ahead of
 *   the client); a client that goes away cancels its question; an export whose client reads
 *   nothing for `STALL_MS`, or that lasts `EXPORT_MAX_MS`, is cut off (its connection closed).
 */

export const WORKERS = 2;
export const PER_USER_EXPORTS = 2;
export const PER_USER = 8;
export const RUNNING = 4;
export const QUEUE = 32;
export const QUEUE_WAIT_MS = 30_000;
export const STALL_MS = 60_000;
export const EXPORT_MAX_MS = 10 * 60_000;
const RETRY_AFTER_S = 5;

interface Task {
  id: number;
  key: string;
  job: ReadJob;
  res: ServerResponse;
  worker: PoolWorker | null;
  /** The worker is done with it (its connection closed). */
  done: () => void;
  gone: boolean;
  queuedTimer: ReturnType<typeof setTimeout> | null;
  stallTimer: ReturnType<typeof setTimeout> | null;
  maxTimer: ReturnType<typeof setTimeout> | null;
}

interface PoolWorker {
  worker: Worker;
  tasks: Map<number, Task>;
}

export interface ReadStats {
  running: number;
  queued: number;
  workers: number;
}

export class HistoryReads {
  private readonly workers: PoolWorker[] = [];
  private readonly queue: Task[] = [];
  private readonly perKey = new Map<string, { all: number; exports: number }>();
  private running = 0;
  private nextId = 1;
  private closed = false;

  constructor(
    private readonly file: string,
    private readonly log: Logger,
    /** The families' exports of their stored days (route, module URL): each worker loads them. */
    private readonly statsExports: ReadonlyArray<{ route: string; module: string }> = [],
  ) {}

  stats(): ReadStats {
    return { running: this.running, queued: this.queue.length, workers: this.workers.length };
  }

  /** Answers `job` on `res` (resolves when the worker is done with it). */
  answer(key: string, job: ReadJob, res: ServerResponse): Promise<void> {
    const n = this.perKey.get(key) ?? { all: 0, exports: 0 };
    if (job.csv && n.exports >= PER_USER_EXPORTS) {
      tooMany(res, `at most ${PER_USER_EXPORTS} history exports at once each: wait for one to finish`);
      return Promise.resolve();
    }
    if (n.all >= PER_USER) {
      tooMany(res, `at most ${PER_USER} history questions at once each: wait for one to finish`);
      return Promise.resolve();
    }
    if (this.closed || (this.running >= RUNNING && this.queue.length >= QUEUE)) {
      sendJson(
        res,
        503,
        { error: 'the history is busy answering others: try again shortly', retryAfterS: RETRY_AFTER_S },
        { 'Retry-After': String(RETRY_AFTER_S) },
      );
      return Promise.resolve();
    }
    n.all++;
    if (job.csv) n.exports++;
    this.perKey.set(key, n);
    return new Promise<void>((resolve) => {
      const task: Task = {
        id: this.nextId++,
        key,
        job,
        res,
        worker: null,
        gone: false,
        queuedTimer: null,
        stallTimer: null,
        maxTimer: null,
        done: () => {
          this.clearTimers(task);
          const c = this.perKey.get(key);
          if (c) {
            c.all--;
            if (job.csv) c.exports--;
            if (c.all <= 0) this.perKey.delete(key);
          }
          resolve();
        },
      };
      res.on('close', () => {
        if (res.writableFinished) return;
        task.gone = true;
        const q = this.queue.indexOf(task);
        if (q >= 0) {
          this.queue.splice(q, 1);
          task.done();
        } else if (task.worker) this.send(task.worker, { type: 'cancel', id: task.id });
      });
      if (this.running < RUNNING) this.start(task);
      else {
        task.queuedTimer = setTimeout(() => {
          const q = this.queue.indexOf(task);
          if (q < 0) return;
          this.queue.splice(q, 1);
          sendJson(
            res,
            503,
            { error: 'the history is busy answering others: try again shortly', retryAfterS: RETRY_AFTER_S },
            { 'Retry-After': String(RETRY_AFTER_S) },
          );
          task.done();
        }, QUEUE_WAIT_MS);
        this.queue.push(task);
      }
    });
  }

  private clearTimers(t: Task): void {
    for (const timer of [t.queuedTimer, t.stallTimer, t.maxTimer]) if (timer) clearTimeout(timer);
    t.queuedTimer = t.stallTimer = t.maxTimer = null;
  }

  private start(task: Task): void {
    if (task.queuedTimer) clearTimeout(task.queuedTimer);
    task.queuedTimer = null;
    const w = this.pick();
    this.running++;
    task.worker = w;
    w.tasks.set(task.id, task);
    this.send(w, { type: 'run', id: task.id, file: this.file, job: task.job });
  }

  private send(w: PoolWorker, m: ToWorker): void {
    w.worker.postMessage(m);
  }

  /** The worker with the fewest questions; a new one while there are fewer than `WORKERS`. */
  private pick(): PoolWorker {
    const idle = this.workers.find((w) => w.tasks.size === 0);
    if (idle) return idle;
    if (this.workers.length < WORKERS) return this.spawn();
    return this.workers.reduce((a, b) => (b.tasks.size < a.tasks.size ? b : a));
  }

  private spawn(): PoolWorker {
    const worker = new Worker(new URL('./read-worker.mjs', import.meta.url), {
      workerData: { statsExports: this.statsExports },
    });
    worker.unref();
    const w: PoolWorker = { worker, tasks: new Map() };
    this.workers.push(w);
    worker.on('message', (m: FromWorker) => this.onMessage(w, m));
    const fail = (why: string): void => {
      const i = this.workers.indexOf(w);
      if (i >= 0) this.workers.splice(i, 1);
      if (!this.closed && w.tasks.size)
        this.log.error('a history read worker stopped: its questions failed', { error: why });
      for (const t of w.tasks.values()) this.finish(w, t, 'failed');
    };
    worker.on('error', (e) => fail(e instanceof Error ? e.message : String(e)));
    worker.on('exit', (code) => fail(`exit code ${code}`));
    return w;
  }

  private onMessage(w: PoolWorker, m: FromWorker): void {
    const t = w.tasks.get(m.id);
    if (!t) return;
    const res = t.res;
    switch (m.type) {
      case 'json':
        if (!t.gone) sendJsonText(res, m.status, m.text);
        return;
      case 'csv-head':
        if (t.gone) return;
        res.writeHead(200, {
          'Content-Type': 'text/csv; charset=utf-8',
          'Content-Disposition': `attachment; filename="shopdeck-${m.name}.csv"`,
          'Cache-Control': 'no-store',
          'X-Content-Type-Options': 'nosniff',
          ...(m.truncated ? { 'X-Shopdeck-Truncated': 'true' } : {}),
        });
        t.maxTimer = setTimeout(() => res.destroy(), EXPORT_MAX_MS);
        this.stalled(t);
        return;
      case 'chunk': {
        if (t.gone) return;
        this.stalled(t);
        if (res.write(m.text)) this.send(w, { type: 'credit', id: t.id });
        else
          res.once('drain', () => {
            this.stalled(t);
            this.send(w, { type: 'credit', id: t.id });
          });
        return;
      }
      case 'end':
        if (!t.gone) res.end();
        return;
      case 'error':
        this.log.error('history: a question failed', { route: t.job.route, error: m.message });
        if (t.gone) return;
        if (res.headersSent) res.destroy();
        else sendJson(res, 500, { error: 'the history could not answer: see the server log' });
        return;
      case 'done':
        this.finish(w, t, 'done');
        return;
    }
  }

  /** The export's client must read within `STALL_MS`. */
  private stalled(t: Task): void {
    if (t.stallTimer) clearTimeout(t.stallTimer);
    t.stallTimer = setTimeout(() => t.res.destroy(), STALL_MS);
  }

  private finish(w: PoolWorker, t: Task, how: 'done' | 'failed'): void {
    if (!w.tasks.delete(t.id)) return;
    this.running--;
    if (how === 'failed' && !t.gone && !t.res.writableEnded) {
      if (t.res.headersSent) t.res.destroy();
      else sendJson(t.res, 500, { error: 'the history could not answer: see the server log' });
    }
    t.done();
    const next = this.queue.shift();
    if (next && !this.closed) this.start(next);
  }

  close(): void {
    this.closed = true;
    for (const t of this.queue.splice(0)) {
      if (!t.res.headersSent) sendJson(t.res, 503, { error: 'the history is closing' });
      t.done();
    }
    for (const w of this.workers.splice(0)) void w.worker.terminate();
  }
}

function tooMany(res: ServerResponse, error: string): void {
  sendJson(
    res,
    429,
    { error, retryAfterS: RETRY_AFTER_S },
    { 'Retry-After': String(RETRY_AFTER_S), 'X-Shopdeck-Gateway': 'error' },
  );
}
