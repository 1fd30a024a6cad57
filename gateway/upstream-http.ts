import { createHash } from 'node:crypto';
import http, { type IncomingMessage, type OutgoingHttpHeaders, type ServerResponse } from 'node:http';
import { Writable } from 'node:stream';
import type { SharingHints } from '../src/fleet/contract';
import type { HeldHttp } from './held-session';
import { sendJson } from './http-util';
import type { MachineEntry } from './machines';

/**
 * One upstream per machine, HTTP side: whatever the number of viewers, the gateway's requests to
 * one controller are shared and bounded here, as the family declares (`gateway.sharing`,
 * `SharingHints` in src/fleet/contract.ts). A family without `sharing` is forwarded as before:
 * nothing shared, no limit, no keep-alive.
 *
 * - **Coalesced reads.** A GET that is not a command, has no body, and for which the family's
 *   `shareRead(path, query)` gives a window: identical reads (same machine, method, path and query
 *   and headers as they go upstream, i.e. after the gateway's own changes: held session key,
 *   injected secrets) that arrive while one is in flight join it; those that arrive within
 *   `windowMs` after its answer get that answer again. Headers that are the browser's own
 *   business (user agent, `sec-*`, conditional and cache headers) are dropped from a shared read;
 *   every other header goes upstream and is part of the key (`accept`, `range`, `authorization`…),
 *   so two reads the controller could answer differently are never merged. The key is a hash:
 *   no secret is kept in it.
 * - The shared request runs through the proxy's usual path (`forward` / `answerFromSimulator`:
 *   redirect rewriting, safe answer headers, redaction, held-session retry) into a `Capture`,
 *   whose bytes are then given to each waiter. So redaction and header rules are the same for every
 *   answer; `Set-Cookie` (already dropped there) is dropped again on replay.
 * - Only whole answers up to `maxSharedBytes` are kept, and never the gateway's own failures
 *   (`X-Shopdeck-Gateway: error`: unreachable, timed out, refused…); those are given to the
 *   waiters already joined, as they are. A cut answer cuts every waiter's. An answer larger than
 *   `maxSharedBytes` is streamed to the waiters already joined and not kept.
 * - A browser that leaves takes itself out of the waiters; the upstream request is abandoned only
 *   when no waiter is left (as an unshared one is when its browser leaves).
 * - A command clears the machine's kept answers and closes in-flight reads to newcomers: what was
 *   read before a command is not served after it.
 * - Kept answers are per machine, bounded (`maxCachedAnswers`, `maxCachedBytes`), expired ones
 *   dropped on every use.
 *
 * - **Concurrency.** At most `maxConcurrentReads` reads (every non-command request, shared or
 *   not) upstream at once per machine; more wait in a FIFO queue of at most `maxQueuedReads`.
 *   A full queue, or a read that waited longer than `queueTimeoutMs` (default: the gateway's
 *   timeout), is answered 503 `{ error, gateway: true }`. A waiting read whose browser left is
 *   dropped from the queue.
 * - **Commands** never wait in that queue, are never shared, kept or retried (the held session's
 *   rule: a command whose key expired is not re-sent): they go at once, in the order they reach
 *   this point, each on a fresh connection (never on a kept-alive socket the controller may be
 *   closing at that moment: a command is not lost to a stale socket).
 * - **Keep-alive.** Reads to an `http:` controller use one agent per machine, keep-alive as the
 *   family declares. `https:` controllers keep one pinned TLS socket per request
 *   (tls-pin.ts `connectPinned`, in `forward`): no keep-alive there for now.
 * - Simulated machines get the same sharing and limits (they stand in for hardware).
 * - **Counters** per machine (`stats(id)`): upstream requests, shared answers, queued reads, …
 */

export interface UpstreamLimits {
  /** Largest answer kept and replayed; larger ones are streamed to the waiters already joined. */
  maxSharedBytes: number;
  /** Reads waiting for a slot, per machine; one more is answered 503. */
  maxQueuedReads: number;
  /** Longest wait for a slot, ms (default: the gateway's timeout towards a controller). */
  queueTimeoutMs?: number;
  /** Kept answers per machine. */
  maxCachedAnswers: number;
  /** Bytes of kept answers per machine. */
  maxCachedBytes: number;
}

export const DEFAULT_UPSTREAM_LIMITS: UpstreamLimits = {
  maxSharedBytes: 4 * 1024 * 1024,
  maxQueuedReads: 64,
  maxCachedAnswers: 32,
  maxCachedBytes: 16 * 1024 * 1024,
};

/** A family's window is capped: a shared answer is never older than this. */
const MAX_WINDOW_MS = 60_000;
/** A kept-alive socket unused this long is closed (shorter than common server keep-alive timeouts). */
const IDLE_SOCKET_MS = 4_000;

export interface UpstreamStats {
  /** Requests sent to the controller (or its simulator): reads, commands, held-session re-sends. */
  upstreamRequests: number;
  /** Of which commands. */
  commands: number;
  /** Answers a browser got from another browser's upstream request (joined or kept). */
  sharedAnswers: number;
  /** Reads that had to wait for a slot. */
  queuedReads: number;
  /** Reads answered 503 (queue full, waited too long). */
  refusedReads: number;
  /** Now: reads upstream. */
  readsInFlight: number;
  /** Now: reads waiting for a slot. */
  queueLength: number;
  /** Now: browsers waiting on a shared read in flight. */
  waitingBrowsers: number;
  /** Now: answers kept (not expired). */
  cachedAnswers: number;
}

export interface UpstreamDeps {
  /** The family's declaration for the machine, if any. */
  sharingOf(m: MachineEntry): SharingHints | undefined;
  timeoutMs: number;
  now(): number;
  /** The gateway's agent without keep-alive (commands, families without keep-alive). */
  httpAgent: http.Agent;
  scrub(text: string): string;
  limits?: Partial<UpstreamLimits>;
}

/** One proxied request, as `proxy-http.ts` has it once the gateway's own changes are made. */
export interface UpstreamCall {
  machine: MachineEntry;
  req: IncomingMessage;
  res: ServerResponse;
  method: string;
  /** Canonical controller path (what the family's `shareRead` sees). */
  path: string;
  /** The browser's query, before the gateway's changes (what the family's `shareRead` sees). */
  query: URLSearchParams;
  /** Path and query as they go upstream. */
  pathAndQuery: string;
  /** Headers as they go upstream; a shared read drops the browser's own ones from this object. */
  headers: Record<string, string>;
  isCommand: boolean;
  held: HeldHttp | null;
}

/**
 * Sends the request upstream and answers into `sink` (the browser's response, or a capture shared
 * by several browsers), with `agent` for `http:` controllers.
 */
export type UpstreamRun = (sink: ServerResponse, agent: http.Agent, held: HeldHttp | null) => Promise<void>;

interface Answer {
  status: number;
  headers: Record<string, string | string[]>;
  body: Buffer;
}

interface Head {
  status: number;
  headers: Record<string, string | string[]>;
}

/** Request headers that are one browser's business: not sent for a shared read, not in its key. */
const PER_BROWSER =
  /^(user-agent|dnt|priority|cache-control|pragma|if-none-match|if-modified-since|if-match|if-unmodified-since|upgrade-insecure-requests|save-data|sec-.*)$/i;

/** Answer headers never replayed to another browser. */
const NOT_REPLAYED = new Set([
  'set-cookie',
  'content-length',
  'transfer-encoding',
  'connection',
  'keep-alive',
]);

const noop = (): void => undefined;

function zeroStats(): UpstreamStats {
  return {
    upstreamRequests: 0,
    commands: 0,
    sharedAnswers: 0,
    queuedReads: 0,
    refusedReads: 0,
    readsInFlight: 0,
    queueLength: 0,
    waitingBrowsers: 0,
    cachedAnswers: 0,
  };
}

function hasBody(req: IncomingMessage): boolean {
  const cl = req.headers['content-length'];
  return (cl !== undefined && cl.trim() !== '0') || req.headers['transfer-encoding'] !== undefined;
}

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

function bodyAllowed(status: number): boolean {
  return status >= 200 && status !== 204 && status !== 304;
}

function replayHeaders(
  headers: Readonly<Record<string, string | string[]>>,
): Record<string, string | string[]> {
  const out: Record<string, string | string[]> = {};
  for (const [k, v] of Object.entries(headers)) if (!NOT_REPLAYED.has(k)) out[k] = v;
  return out;
}

/** Gives a whole answer to one browser. */
function replay(res: ServerResponse, a: Answer): boolean {
  if (res.destroyed || res.headersSent) return false;
  const headers = replayHeaders(a.headers);
  if (bodyAllowed(a.status)) headers['content-length'] = String(a.body.length);
  res.writeHead(a.status, headers);
  res.end(a.body);
  return true;
}

function refuseBusy(res: ServerResponse, error: string): void {
  if (res.headersSent || res.destroyed) return;
  sendJson(res, 503, { error, gateway: true }, { 'Retry-After': '1' });
}

function headerValue(v: number | string | readonly string[]): string | string[] {
  return typeof v === 'number' ? String(v) : typeof v === 'string' ? v : [...v];
}

// ---------------------------------------------------------------- the capture

/** What a capture tells the shared read it belongs to. */
interface CaptureListener {
  /** The whole answer, within the size limit. */
  complete(a: Answer): void;
  /** The answer outgrew the limit: `buffered` so far, then `chunk`s, then `endStream`. */
  overflow(head: Head, buffered: Buffer, cb: (err?: Error | null) => void): void;
  chunk(chunk: Buffer, cb: (err?: Error | null) => void): void;
  endStream(): void;
  /** Ended without a whole answer (cut, abandoned). */
  failed(): void;
}

/**
 * Stands in for a browser's `ServerResponse` where the proxy writes a shared read's answer. It
 * implements what `forward`, `answerFromSimulator`, `sendJson` and the held session use of a
 * response: `writeHead`, the header methods, `headersSent`, `statusCode`, and the Writable side
 * (`write`/`end`, `pipeline` into it, `destroy`, `'close'`, `writableFinished`).
 */
class Capture extends Writable {
  statusCode = 200;
  private readonly pendingHeaders: Record<string, string | string[]> = {};
  private head: Head | null = null;
  private chunks: Buffer[] = [];
  private size = 0;
  private streaming = false;
  private whole = false;

  constructor(
    private readonly cap: number,
    private readonly listener: CaptureListener,
    /** Each chunk before it is kept: false treats the answer as larger than `cap`. */
    private readonly take?: (bytes: number) => boolean,
  ) {
    super();
    // Failures reach the waiters through the listener; an error event has nobody else to tell.
    this.on('error', noop);
  }

  get headersSent(): boolean {
    return this.head !== null;
  }

  setHeader(name: string, value: number | string | readonly string[]): this {
    this.pendingHeaders[name.toLowerCase()] = headerValue(value);
    return this;
  }

  getHeader(name: string): string | string[] | undefined {
    return this.pendingHeaders[name.toLowerCase()];
  }

  hasHeader(name: string): boolean {
    return name.toLowerCase() in this.pendingHeaders;
  }

  removeHeader(name: string): void {
    delete this.pendingHeaders[name.toLowerCase()];
  }

  writeHead(status: number, a?: string | OutgoingHttpHeaders, b?: OutgoingHttpHeaders): this {
    if (this.head) throw new Error('Cannot write headers after they are sent to the client');
    const given = typeof a === 'string' ? b : a;
    const headers: Record<string, string | string[]> = { ...this.pendingHeaders };
    for (const [k, v] of Object.entries(given ?? {}))
      if (v !== undefined) headers[k.toLowerCase()] = headerValue(v);
    this.statusCode = status;
    this.head = { status, headers };
    return this;
  }

  private ensureHead(): Head {
    if (!this.head) this.writeHead(this.statusCode);
    return this.head ?? { status: this.statusCode, headers: {} };
  }

  override _write(chunk: Buffer, _enc: BufferEncoding, cb: (err?: Error | null) => void): void {
    const head = this.ensureHead();
    if (this.streaming) {
      this.listener.chunk(chunk, cb);
      return;
    }
    this.chunks.push(chunk);
    this.size += chunk.length;
    if (this.size <= this.cap && (this.take?.(chunk.length) ?? true)) {
      cb();
      return;
    }
    this.streaming = true;
    const buffered = Buffer.concat(this.chunks);
    this.chunks = [];
    this.listener.overflow(head, buffered, cb);
  }

  override _final(cb: (err?: Error | null) => void): void {
    const head = this.ensureHead();
    this.whole = true;
    if (this.streaming) this.listener.endStream();
    else this.listener.complete({ ...head, body: Buffer.concat(this.chunks) });
    this.chunks = [];
    cb();
  }

  override _destroy(err: Error | null, cb: (err?: Error | null) => void): void {
    if (!this.whole) {
      this.chunks = [];
      this.listener.failed();
    }
    cb(err);
  }
}

/**
 * The capture where the proxy expects a browser's response: it has every part of one the proxy
 * uses (see `Capture`); the rest of `ServerResponse` (socket, trailers…) it does not pretend to.
 */
function asResponse(c: Capture): ServerResponse {
  return c as unknown as ServerResponse;
}

/** A captured answer outgrew its cap (or the budget of whoever waits for it): nothing kept. */
export class AnswerTooLarge extends Error {
  constructor(readonly cap: number) {
    super(`the answer is larger than ${cap} bytes`);
  }
}

/**
 * A response for the gateway's own reads (the watch): the whole answer, up to `cap` bytes, or a
 * failure (cut, abandoned, larger than `cap`).
 */
export function captureAnswer(
  cap: number,
  /** Each chunk before it is kept (the read socket's budget): false fails it as too large. */
  take?: (bytes: number) => boolean,
): {
  res: ServerResponse;
  answer: Promise<{ status: number; headers: Answer['headers']; body: Buffer }>;
} {
  let resolve: (a: { status: number; headers: Answer['headers']; body: Buffer }) => void = noop;
  let reject: (e: Error) => void = noop;
  const answer = new Promise<{ status: number; headers: Answer['headers']; body: Buffer }>((ok, fail) => {
    resolve = ok;
    reject = fail;
  });
  const c = new Capture(
    cap,
    {
      complete: (a) => resolve({ status: a.status, headers: a.headers, body: a.body }),
      overflow: (_h, _b, cb) => {
        reject(new AnswerTooLarge(cap));
        cb(new Error('too large'));
      },
      chunk: (_c, cb) => cb(new Error('too large')),
      endStream: noop,
      failed: () => reject(new Error('the answer was cut or abandoned')),
    },
    take,
  );
  return { res: asResponse(c), answer };
}

// ---------------------------------------------------------------- one machine

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

class MachineLink {
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
    // `https:` controllers ignore it: `forward` gives each request its own pinned TLS socket.
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

// ---------------------------------------------------------------- the gateway's

export class UpstreamHttp {
  private readonly links = new Map<string, MachineLink>();
  private readonly limits: UpstreamLimits;

  constructor(private readonly deps: UpstreamDeps) {
    this.limits = { ...DEFAULT_UPSTREAM_LIMITS, ...deps.limits };
  }

  private link(m: MachineEntry): MachineLink {
    let l = this.links.get(m.id);
    if (!l) {
      l = new MachineLink(m, this.deps, this.limits);
      this.links.set(m.id, l);
    }
    return l;
  }

  /**
   * Sends one proxied request upstream as the machine's family declares. Resolves once the
   * request is handed on (a shared read's answer may come later); `run` is not called for a read
   * answered from a kept answer or joined to one in flight.
   */
  async send(r: UpstreamCall, run: UpstreamRun): Promise<void> {
    const sharing = this.deps.sharingOf(r.machine);
    const link = this.link(r.machine);
    if (!sharing) {
      link.stats.upstreamRequests++;
      if (r.isCommand) link.stats.commands++;
      await run(r.res, this.deps.httpAgent, link.counted(r.held, null));
      return;
    }
    if (r.isCommand) {
      await link.command(r, run);
      return;
    }
    const windowMs = r.method === 'GET' && !hasBody(r.req) ? this.windowOf(sharing, r) : null;
    if (windowMs === null) await link.read(r, sharing, run);
    else link.sharedRead(r, sharing, run, windowMs);
  }

  private windowOf(sharing: SharingHints, r: UpstreamCall): number | null {
    let w: number | null;
    try {
      w = sharing.shareRead?.(r.path, new URLSearchParams(r.query)) ?? null;
    } catch {
      return null;
    }
    if (w === null || !Number.isFinite(w) || w < 0) return null;
    return Math.min(w, MAX_WINDOW_MS);
  }

  stats(id: string): UpstreamStats {
    return this.links.get(id)?.snapshot() ?? zeroStats();
  }

  /** Gateway close: queued reads forgotten (their browsers are closed with the server), agents ended. */
  close(): void {
    for (const l of this.links.values()) l.close();
  }
}
