import { createHash } from 'node:crypto';
import http, { type ServerResponse } from 'node:http';
import type { SharingHints } from '../src/fleet/contract';
import type { HeldHttp } from './held-types';
import { sendJson } from './http-util';
import type { MachineEntry } from './machines';
import {
  asResponse,
  Capture,
  noop,
  refuseBusy,
  replay,
  replayHeaders,
  type CaptureListener,
} from './upstream-capture';
import {
  zeroStats,
  type Answer,
  type Head,
  type UpstreamCall,
  type UpstreamDeps,
  type UpstreamLimits,
  type UpstreamRun,
  type UpstreamStats,
} from './upstream-types';

/**
 * One machine's HTTP upstream (upstream-http.ts): its read slots and their queue, its shared
 * reads in flight and kept answers, its keep-alive agent, its counters.
 */

/** A kept-alive socket unused this long is closed (shorter than common server keep-alive timeouts). */
const IDLE_SOCKET_MS = 4_000;

/** Request headers that are one browser's business: not sent for a shared read, not in its key. */
const PER_BROWSER =
  /^(user-agent|dnt|priority|cache-control|pragma|if-none-match|if-modified-since|if-match|if-unmodified-since|upgrade-insecure-requests|save-data|sec-.*)$/i;

function keyOf(method: string, pathAndQuery: string, headers: Record<string, string>): string {
  const h = createHash('sha256');
  h.update(method).update('\0').update(pathAndQuery);
  const names = Object.keys(headers).sort();
  for (const k of names)
    h.update('\0')
      .update(k.toLowerCase())
      .update(':')
      .update(headers[k] ?? '');
  return h.digest('base64url');
}

interface Ticket {
  start(): void;
  timer: ReturnType<typeof setTimeout>;
}

interface Kept {
  answer: Answer;
  until: number;
}

/** One upstream read shared by the browsers that asked for it while it was in flight. */
class SharedRead implements CaptureListener {
  readonly waiters = new Set<ServerResponse>();
  first: ServerResponse | null = null;
  /** Newcomers may join (false once answered, streaming, abandoned, or a command was sent). */
  joinable = true;
  /** A command was sent while it was in flight: its answer is not kept. */
  stale = false;
  /**
   * The held session said the key expired and a re-send waits for a new one: an answer written
   * meanwhile is the session's refusal, not the controller's answer to this read (not kept).
   */
  renewing = false;
  settled = false;
  cancelQueue: () => void = noop;
  readonly capture: Capture;

  constructor(
    private readonly link: MachineLink,
    readonly key: string,
    private readonly windowMs: number,
    cap: number,
  ) {
    this.capture = new Capture(cap, this);
  }

  join(res: ServerResponse): void {
    this.first ??= res;
    this.waiters.add(res);
    res.once('close', () => this.leave(res));
  }

  private leave(res: ServerResponse): void {
    if (this.settled || !this.waiters.delete(res) || this.waiters.size > 0) return;
    // Nobody waits any more: not queued, not joinable, the upstream request abandoned.
    this.joinable = false;
    this.settled = true;
    this.link.forget(this);
    this.cancelQueue();
    this.capture.destroy();
  }

  /** Answered 503 by the queue: every waiter gets it, nothing kept. */
  refuse(error: string): void {
    this.settle();
    for (const w of this.waiters) refuseBusy(w, error);
    this.waiters.clear();
  }

  private settle(): void {
    this.settled = true;
    this.joinable = false;
    this.link.forget(this);
  }

  private shared(res: ServerResponse): void {
    if (res !== this.first) this.link.stats.sharedAnswers++;
  }

  complete(a: Answer): void {
    this.settle();
    const gatewaysOwn = a.headers['x-shopdeck-gateway'] !== undefined;
    if (!this.stale && !this.renewing && !gatewaysOwn && this.windowMs > 0)
      this.link.keep(this.key, a, this.windowMs);
    for (const w of this.waiters) if (replay(w, a)) this.shared(w);
    this.waiters.clear();
  }

  overflow(head: Head, buffered: Buffer, cb: (err?: Error | null) => void): void {
    // Too large to keep: streamed to those already joined, nobody else joins.
    this.joinable = false;
    this.link.forget(this);
    const headers = replayHeaders(head.headers);
    const length = head.headers['content-length'];
    if (typeof length === 'string') headers['content-length'] = length;
    for (const w of this.waiters) if (!w.destroyed && !w.headersSent) w.writeHead(head.status, headers);
    this.chunk(buffered, cb);
  }

  /** Writes to every waiter; `cb` once the slowest has room again (or left). */
  chunk(chunk: Buffer, cb: (err?: Error | null) => void): void {
    let waiting = 1;
    const one = (): void => {
      if (--waiting === 0) cb();
    };
    for (const w of this.waiters) {
      if (w.destroyed || w.writableEnded) continue;
      if (w.write(chunk)) continue;
      waiting++;
      let done = false;
      const room = (): void => {
        if (done) return;
        done = true;
        w.off('drain', room);
        w.off('close', room);
        one();
      };
      w.on('drain', room);
      w.on('close', room);
    }
    one();
  }

  endStream(): void {
    this.settle();
    for (const w of this.waiters) {
      if (w.destroyed || w.writableEnded) continue;
      w.end();
      this.shared(w);
    }
    this.waiters.clear();
  }

  failed(): void {
    if (this.settled && this.waiters.size === 0) return;
    // Cut or abandoned midway: every waiter's answer is cut the same way, nothing kept.
    this.settle();
    for (const w of this.waiters) w.destroy();
    this.waiters.clear();
  }

  /** The proxy threw instead of answering: the waiters get what a lone browser would. */
  crashed(e: unknown, scrub: (text: string) => string): void {
    if (this.capture.writableFinished || this.capture.destroyed) return;
    if (this.capture.headersSent) {
      this.capture.destroy();
      return;
    }
    sendJson(asResponse(this.capture), 500, {
      error: scrub(e instanceof Error ? e.message : String(e)),
    });
  }
}

export class MachineLink {
  readonly stats = zeroStats();
  private active = 0;
  private readonly queue: Ticket[] = [];
  private readonly inFlight = new Map<string, SharedRead>();
  private readonly kept = new Map<string, Kept>();
  private keptBytes = 0;
  private agent: http.Agent | null = null;

  constructor(
    private readonly m: MachineEntry,
    private readonly deps: UpstreamDeps,
    private readonly limits: UpstreamLimits,
  ) {}

  // ---------------------------------------------------------------- commands

  /** A command goes at once, on a fresh connection; what was read before it is not served after. */
  command(r: UpstreamCall, run: UpstreamRun): Promise<void> {
    this.kept.clear();
    this.keptBytes = 0;
    for (const g of this.inFlight.values()) {
      g.joinable = false;
      g.stale = true;
    }
    this.inFlight.clear();
    this.stats.commands++;
    this.stats.upstreamRequests++;
    return run(r.res, this.deps.httpAgent, this.counted(r.held, null));
  }

  // ---------------------------------------------------------------- reads

  /** A read that is not shared: still one of the machine's limited reads. */
  read(r: UpstreamCall, sharing: SharingHints, run: UpstreamRun): Promise<void> {
    const { res } = r;
    // The browser left before the read came this far (its 'close' is behind us): not sent.
    if (res.destroyed) {
      r.req.resume();
      return Promise.resolve();
    }
    return new Promise<void>((resolve, reject) => {
      let cancel = noop;
      const gone = (): void => {
        cancel();
        resolve();
      };
      res.once('close', gone);
      cancel = this.admit(
        () => {
          res.off('close', gone);
          let released = false;
          const release = (): void => {
            if (released) return;
            released = true;
            this.release();
          };
          // The slot is released on every way the read ends: its answer given or cut, the browser
          // gone, a timeout or an error (each ends `res`: 'close'), or the proxy throwing before
          // it could answer (below: the caller answers then; a capture may never be closed).
          res.once('close', release);
          this.stats.upstreamRequests++;
          let ran: Promise<void>;
          try {
            ran = run(res, this.readAgent(sharing), this.counted(r.held, null));
          } catch (e) {
            ran = Promise.reject(e instanceof Error ? e : new Error(String(e)));
          }
          ran.then(resolve, (e: unknown) => {
            release();
            // Half an answer written: it is cut, as a broken connection would cut it.
            if (res.headersSent && !res.writableFinished) res.destroy();
            reject(e instanceof Error ? e : new Error(String(e)));
          });
        },
        (error) => {
          res.off('close', gone);
          r.req.resume();
          refuseBusy(res, error);
          resolve();
        },
      );
    });
  }

  /** A read answered from a kept answer, a read in flight, or a new shared upstream read. */
  sharedRead(r: UpstreamCall, sharing: SharingHints, run: UpstreamRun, windowMs: number): void {
    // The browser left before the read came this far (its 'close' is behind us): not sent.
    if (r.res.destroyed) {
      r.req.resume();
      return;
    }
    for (const k of Object.keys(r.headers)) if (PER_BROWSER.test(k)) delete r.headers[k];
    const key = keyOf(r.method, r.pathAndQuery, r.headers);
    const kept = this.lookup(key);
    if (kept) {
      r.req.resume();
      if (replay(r.res, kept)) this.stats.sharedAnswers++;
      return;
    }
    const joined = this.inFlight.get(key);
    if (joined?.joinable) {
      r.req.resume();
      joined.join(r.res);
      return;
    }
    const g = new SharedRead(this, key, windowMs, this.limits.maxSharedBytes);
    this.inFlight.set(key, g);
    g.join(r.res);
    g.cancelQueue = this.admit(
      () => {
        let released = false;
        g.capture.once('close', () => {
          if (released) return;
          released = true;
          this.release();
        });
        this.stats.upstreamRequests++;
        const sink = asResponse(g.capture);
        // Released when the capture closes: answered, cut, abandoned (every waiter gone), or the
        // proxy's throw answered by `crashed` (which ends or destroys it).
        let ran: Promise<void>;
        try {
          ran = run(sink, this.readAgent(sharing), this.counted(r.held, sink, g));
        } catch (e) {
          ran = Promise.reject(e instanceof Error ? e : new Error(String(e)));
        }
        ran.catch((e: unknown) => g.crashed(e, this.deps.scrub));
      },
      (error) => g.refuse(error),
    );
  }

  forget(g: SharedRead): void {
    if (this.inFlight.get(g.key) === g) this.inFlight.delete(g.key);
  }

  // ---------------------------------------------------------------- kept answers

  private lookup(key: string): Answer | null {
    this.prune();
    return this.kept.get(key)?.answer ?? null;
  }

  keep(key: string, answer: Answer, windowMs: number): void {
    this.prune();
    const old = this.kept.get(key);
    if (old) {
      this.kept.delete(key);
      this.keptBytes -= old.answer.body.length;
    }
    if (answer.body.length > this.limits.maxCachedBytes) return;
    this.kept.set(key, { answer, until: this.deps.now() + windowMs });
    this.keptBytes += answer.body.length;
    // Oldest first (insertion order) until within bounds.
    for (const [k, v] of this.kept) {
      if (this.kept.size <= this.limits.maxCachedAnswers && this.keptBytes <= this.limits.maxCachedBytes)
        break;
      this.kept.delete(k);
      this.keptBytes -= v.answer.body.length;
    }
  }

  private prune(): void {
    const now = this.deps.now();
    for (const [k, v] of this.kept) {
      if (v.until > now) continue;
      this.kept.delete(k);
      this.keptBytes -= v.answer.body.length;
    }
  }

  // ---------------------------------------------------------------- slots

  private maxReads(): number {
    const n = this.deps.sharingOf(this.m)?.maxConcurrentReads ?? Number.POSITIVE_INFINITY;
    return Number.isNaN(n) ? 1 : Math.max(1, Math.floor(n));
  }

  /**
   * `start` now when a read slot is free and nobody waits, else when one frees up (FIFO);
   * `refused` when the queue is full or the wait is too long. Returns: leave the queue.
   */
  private admit(start: () => void, refused: (error: string) => void): () => void {
    if (this.active < this.maxReads() && this.queue.length === 0) {
      this.active++;
      start();
      return noop;
    }
    if (this.queue.length >= this.limits.maxQueuedReads) {
      this.stats.refusedReads++;
      refused(`${this.m.name} is busy: ${this.queue.length} reads are already waiting for it; try again`);
      return noop;
    }
    const waitMs = this.limits.queueTimeoutMs ?? this.deps.timeoutMs;
    const ticket: Ticket = {
      start,
      timer: setTimeout(() => {
        if (!this.unqueue(ticket)) return;
        this.stats.refusedReads++;
        refused(`${this.m.name} is busy: a read waited ${waitMs} ms for its turn; try again`);
      }, waitMs),
    };
    ticket.timer.unref();
    this.queue.push(ticket);
    this.stats.queuedReads++;
    return () => {
      if (this.unqueue(ticket)) clearTimeout(ticket.timer);
    };
  }

  private unqueue(t: Ticket): boolean {
    const i = this.queue.indexOf(t);
    if (i < 0) return false;
    this.queue.splice(i, 1);
    return true;
  }

  private release(): void {
    this.active--;
    while (this.active < this.maxReads()) {
      const next = this.queue.shift();
      if (!next) break;
      clearTimeout(next.timer);
      this.active++;
      next.start();
    }
  }

  // ---------------------------------------------------------------- connections

  private readAgent(sharing: SharingHints): http.Agent {
    if (!sharing.keepAlive) return this.deps.httpAgent;
    // `https:` controllers ignore it: their reads use the machine's pool of kept pinned TLS
    // connections (tls-pool.ts) under the same `keepAlive`.
    this.agent ??= new http.Agent({
      keepAlive: true,
      keepAliveMsecs: 1000,
      maxFreeSockets: Math.min(this.maxReads(), 16),
      timeout: IDLE_SOCKET_MS,
      scheduling: 'lifo',
    });
    return this.agent;
  }

  /** The held session's hooks, counting its re-sends; a shared read's refusal goes to its capture. */
  counted(held: HeldHttp | null, answerTo: ServerResponse | null, shared?: SharedRead): HeldHttp | null {
    if (!held) return null;
    return {
      retry: (status, resend, dropped, to) => {
        const again = held.retry(
          status,
          (pq) => {
            if (shared) shared.renewing = false;
            this.stats.upstreamRequests++;
            resend(pq);
          },
          dropped,
          to ?? answerTo ?? undefined,
        );
        if (again && shared) shared.renewing = true;
        return again;
      },
    };
  }

  snapshot(): UpstreamStats {
    this.prune();
    let waiting = 0;
    for (const g of this.inFlight.values()) waiting += g.waiters.size;
    return {
      ...this.stats,
      readsInFlight: this.active,
      queueLength: this.queue.length,
      waitingBrowsers: waiting,
      cachedAnswers: this.kept.size,
    };
  }

  close(): void {
    for (const t of this.queue) clearTimeout(t.timer);
    this.queue.length = 0;
    this.kept.clear();
    this.keptBytes = 0;
    this.agent?.destroy();
    this.agent = null;
  }
}
