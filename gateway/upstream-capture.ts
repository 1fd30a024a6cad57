import type { OutgoingHttpHeaders, ServerResponse } from 'node:http';
import { Writable } from 'node:stream';
import { sendJson } from './http-util';
import type { Answer, Head } from './upstream-types';

/**
 * Where the proxy writes an answer that is not one browser's (upstream-http.ts): a shared read's,
 * given to each browser that waits for it, or the gateway's own read (the watch).
 */

/** Answer headers never replayed to another browser. */
const NOT_REPLAYED = new Set([
  'set-cookie',
  'content-length',
  'transfer-encoding',
  'connection',
  'keep-alive',
]);

export const noop = (): void => undefined;

function bodyAllowed(status: number): boolean {
  return status >= 200 && status !== 204 && status !== 304;
}

export function replayHeaders(
  headers: Readonly<Record<string, string | string[]>>,
): Record<string, string | string[]> {
  const out: Record<string, string | string[]> = {};
  for (const [k, v] of Object.entries(headers)) if (!NOT_REPLAYED.has(k)) out[k] = v;
  return out;
}

/** Gives a whole answer to one browser. */
export function replay(res: ServerResponse, a: Answer): boolean {
  if (res.destroyed || res.headersSent) return false;
  const headers = replayHeaders(a.headers);
  if (bodyAllowed(a.status)) headers['content-length'] = String(a.body.length);
  res.writeHead(a.status, headers);
  res.end(a.body);
  return true;
}

export function refuseBusy(res: ServerResponse, error: string): void {
  if (res.headersSent || res.destroyed) return;
  sendJson(res, 503, { error, gateway: true }, { 'Retry-After': '1' });
}

function headerValue(v: number | string | readonly string[]): string | string[] {
  return typeof v === 'number' ? String(v) : typeof v === 'string' ? v : [...v];
}

/** What a capture tells the shared read it belongs to. */
export interface CaptureListener {
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
export class Capture extends Writable {
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
export function asResponse(c: Capture): ServerResponse {
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
