import { sessionGone } from './auth';
import { apiOrigin, wsUrlFor } from './origin';

/**
 * The page's read socket (issue 16; the gateway's side is gateway/read-socket.ts): the polls of
 * every machine on screen go to the console server as messages on one WebSocket instead of one
 * HTTP request each, which costs the browser's main thread a few milliseconds per request
 * (measured: 64 small reads a second, 15 % of a core over `fetch`, under 2 % over a socket).
 *
 * Only reads go here (HttpClient: a GET without a body, not a command, not a binary answer), and
 * only while the socket is open: there is no queue. When it is not open, a read goes over HTTP as
 * before and the socket is opened again in the background (backing off 1 s → 30 s). A read the
 * gateway did not send ("fallback": it is a command, too many at once), or whose answer is larger
 * than the socket takes (1 MiB: it streams over HTTP instead), is read over HTTP. Any other read
 * that was sent is never sent again: when the socket closes under it, it fails as a fetch whose
 * connection broke (a read may be consumed: RepRapFirmware hands each `rr_reply` out once).
 */

export interface SocketAnswer {
  status: number;
  headers: Headers;
  text: string;
}

interface Pending {
  settle(a: SocketAnswer | null): void;
  fail(e: Error): void;
}

/** Reads waiting for their answer at most; more go over HTTP. */
const MAX_PENDING = 256;
const RETRY_FIRST_MS = 1000;
const RETRY_MAX_MS = 30_000;

export class ReadSocket {
  private ws: WebSocket | null = null;
  private open = false;
  private nextId = 1;
  private readonly pending = new Map<number, Pending>();
  private failures = 0;
  /** Not before this time (ms since epoch) is the socket tried again. */
  private notBefore = 0;
  /** Answers read over the socket and reads sent over HTTP instead (tests, benchmarks). */
  readonly counts = { socket: 0, http: 0 };

  constructor(
    private readonly url: string = wsUrlFor(`${apiOrigin()}/api/reads`),
    private readonly now: () => number = Date.now,
    private readonly random: () => number = Math.random,
  ) {}

  /**
   * Sends a read over the socket when it is open. Null: not open now (read it over HTTP; the
   * socket is being opened). The promise gives the answer, or null: the gateway did not send it,
   * read it over HTTP. It rejects when `signal` aborts (a timeout, a stopped session: the answer
   * is not waited for) and when the socket closes before the answer came (the read is not sent
   * again).
   */
  read(
    url: string,
    headers: Record<string, string>,
    signal: AbortSignal,
  ): Promise<SocketAnswer | null> | null {
    if (!this.open || !this.ws || this.pending.size >= MAX_PENDING) {
      this.connect();
      this.counts.http++;
      return null;
    }
    const ws = this.ws;
    const id = this.nextId++;
    // The gateway takes the path on the console's own origin (tests give HttpClient an absolute one).
    const target = /^[a-z]+:\/\//i.test(url) ? pathOf(url) : url;
    return new Promise<SocketAnswer | null>((resolve, reject) => {
      const onAbort = (): void => {
        if (!this.pending.delete(id)) return;
        if (ws.readyState === ws.OPEN) ws.send(JSON.stringify({ cancel: id }));
        reject(new Error('aborted'));
      };
      this.pending.set(id, {
        settle: (a) => {
          signal.removeEventListener('abort', onAbort);
          if (a) this.counts.socket++;
          else this.counts.http++;
          resolve(a);
        },
        fail: (e) => {
          signal.removeEventListener('abort', onAbort);
          reject(e);
        },
      });
      signal.addEventListener('abort', onAbort);
      ws.send(JSON.stringify({ id, url: target, headers }));
    });
  }

  /** Closes the socket (the page goes away); later reads open it again. */
  close(): void {
    this.ws?.close(1000, 'the page is leaving');
    this.dropped();
  }

  private connect(): void {
    if (this.ws || this.now() < this.notBefore) return;
    let ws: WebSocket;
    try {
      ws = new globalThis.WebSocket(this.url);
    } catch {
      this.failed();
      return;
    }
    this.ws = ws;
    ws.onopen = () => {
      this.open = true;
      this.failures = 0;
    };
    ws.onmessage = (ev: MessageEvent) => this.answer(ev.data);
    ws.onclose = (ev?: CloseEvent) => {
      // The console's own session ended (read-socket.ts on the server closes 4401 for that only).
      if (ev?.code === 4401) sessionGone();
      if (this.ws !== ws) return;
      // Closed before it ever opened: the gateway refused it (logged out) or is not there.
      if (!this.open) this.failed();
      else this.notBefore = this.now() + RETRY_FIRST_MS;
      this.dropped();
    };
  }

  /** The socket is gone: every read still waiting fails as a fetch whose connection broke. */
  private dropped(): void {
    this.ws = null;
    this.open = false;
    const waiting = [...this.pending.values()];
    this.pending.clear();
    for (const p of waiting) p.fail(new Error('the read socket closed'));
  }

  private failed(): void {
    const raw = Math.min(RETRY_MAX_MS, RETRY_FIRST_MS * 2 ** this.failures++);
    this.notBefore = this.now() + Math.round(raw * (0.7 + 0.3 * this.random()));
  }

  private answer(data: unknown): void {
    const msg = parseAnswer(data);
    if (!msg) {
      // Not what the gateway sends: nothing on this socket is trusted any more.
      this.ws?.close(1002, 'malformed answer');
      this.dropped();
      return;
    }
    const p = this.pending.get(msg.id);
    if (!p) return; // given up already (aborted)
    this.pending.delete(msg.id);
    p.settle(msg.answer);
  }
}

function pathOf(url: string): string {
  const u = new URL(url);
  return u.pathname + u.search;
}

/** One message of the gateway, checked: `{id, status, headers, body}` or `{id, fallback}`. */
export function parseAnswer(data: unknown): { id: number; answer: SocketAnswer | null } | null {
  if (typeof data !== 'string') return null;
  let v: unknown;
  try {
    v = JSON.parse(data);
  } catch {
    return null;
  }
  if (typeof v !== 'object' || v === null) return null;
  const r = v as Record<string, unknown>;
  if (typeof r.id !== 'number' || !Number.isInteger(r.id)) return null;
  if (typeof r.fallback === 'string') return { id: r.id, answer: null };
  const { status, body, headers } = r;
  if (typeof status !== 'number' || !Number.isInteger(status) || status < 100 || status > 999) return null;
  if (typeof body !== 'string' || typeof headers !== 'object' || headers === null) return null;
  const h = new Headers();
  for (const [k, val] of Object.entries(headers)) {
    if (typeof val !== 'string') return null;
    try {
      h.set(k, val);
    } catch {
      return null;
    }
  }
  return { id: r.id, answer: { status, headers: h, text: body } };
}

let shared: ReadSocket | null = null;

/** The console's page uses a read socket from now on (boot.ts); tests and Node never do. */
export function startReadSocket(socket: ReadSocket | null = new ReadSocket()): ReadSocket | null {
  shared?.close();
  shared = socket;
  return socket;
}

/** The page's read socket, when it has one. */
export function readSocket(): ReadSocket | null {
  return shared;
}
