import type { z } from 'zod/mini';
import { sessionGone } from './auth';
import { commandScope, DEADLINE_GRACE_MS } from './commands';
import { LinkError, protocolError, wordsOf } from './errors';
import { CONSOLE_HEADERS, machineBase } from './origin';
import { readSocket, type SocketAnswer } from './read-socket';

/**
 * Typed HTTP client for one machine. Every request goes to the console's own origin,
 * `/machines/<id>/<controller path>`; the gateway (or msw, in tests) answers.
 */

export type QueryValue = string | number | boolean | null | undefined;

export interface RequestOptions {
  method?: 'GET' | 'POST' | 'PUT' | 'DELETE' | 'PATCH';
  /** Controller path, e.g. "/progress" or "rest/v1/status" (a leading slash is added). */
  path: string;
  query?: Record<string, QueryValue>;
  headers?: Record<string, string>;
  body?: BodyInit | null;
  /** JSON body: serialized and sent with `Content-Type: application/json`. */
  json?: unknown;
  /** Per-request timeout (ms); the client default applies otherwise. */
  timeoutMs?: number;
  /**
   * Set for machine commands: sent as `X-Shopdeck-Command` for the audit log, with what is left of
   * the command's deadline (`X-Shopdeck-Deadline`) while the command runner performs it.
   */
  commandId?: string;
  signal?: AbortSignal;
}

/** Turns a non-2xx answer (or a 200 that the vendor means as a failure) into a LinkError. */
export type VendorErrorParser = (status: number, body: unknown, text: string) => LinkError | null;

export interface HttpClientOptions {
  machineId: string;
  /** Default per-request timeout. */
  timeoutMs?: number;
  /** Serialize every request to this machine (fragile controllers: xTool is an ESP32). */
  serial?: boolean;
  /** Vendor-specific error bodies. */
  parseError?: VendorErrorParser;
  /** Extra headers on every request (e.g. a session key), computed per request. */
  headers?: () => Record<string, string>;
  /** Base URL prefix; defaults to `/machines/<id>`. */
  base?: string;
}

export interface RawResponse {
  status: number;
  headers: Headers;
  text: string;
}

/** The head of an answer, from `fetch` or from the page's read socket (read-socket.ts). */
interface AnswerHead {
  status: number;
  ok: boolean;
  headers: Headers;
}

export class HttpClient {
  readonly machineId: string;
  readonly base: string;
  private readonly timeoutMs: number;
  private readonly serial: boolean;
  private readonly parseError: VendorErrorParser | undefined;
  private readonly extraHeaders: (() => Record<string, string>) | undefined;
  private tail: Promise<unknown> = Promise.resolve();
  /** Number of requests started but not finished; never more than 1 when serial. */
  inFlight = 0;
  maxInFlight = 0;

  constructor(opts: HttpClientOptions) {
    this.machineId = opts.machineId;
    this.base = opts.base ?? machineBase(opts.machineId);
    this.timeoutMs = opts.timeoutMs ?? 8000;
    this.serial = opts.serial ?? false;
    this.parseError = opts.parseError;
    this.extraHeaders = opts.headers;
  }

  url(path: string, query?: Record<string, QueryValue>): string {
    const p = path.startsWith('/') ? path : `/${path}`;
    let u = this.base + p;
    if (query) {
      const qs = new URLSearchParams();
      for (const [k, v] of Object.entries(query)) if (v !== undefined && v !== null) qs.append(k, String(v));
      const s = qs.toString();
      if (s) u += (u.includes('?') ? '&' : '?') + s;
    }
    return u;
  }

  /** Request and return the raw text. Non-2xx answers throw (after the vendor parser had a look). */
  raw(opts: RequestOptions): Promise<RawResponse> {
    const run = () => this.doFetch(opts);
    if (!this.serial) return run();
    const next = this.tail.then(run, run);
    this.tail = next.catch(() => undefined);
    return next;
  }

  /** Request, parse JSON leniently (whatever the content type), validate with `schema`. */
  async json<S extends z.ZodMiniType>(opts: RequestOptions, schema: S): Promise<z.output<S>> {
    const res = await this.raw(opts);
    const body = parseJsonLenient(res.text);
    if (body === NOT_JSON) {
      throw new LinkError(
        'protocol',
        `Unexpected answer from ${opts.path}: not JSON (${preview(res.text)})`,
        {
          path: '(root)',
        },
      );
    }
    const vendor = this.parseError?.(res.status, body, res.text);
    if (vendor) throw vendor;
    const parsed = schema.safeParse(body);
    if (!parsed.success) throw protocolError(opts.path, parsed.error);
    return parsed.data;
  }

  /** Binary answer (images, downloads). Non-2xx answers throw like `raw`. */
  async blob(opts: RequestOptions): Promise<{ blob: Blob; headers: Headers }> {
    const got = await this.exchange(opts, true);
    if (!got.res.ok) throw this.failed(got.res, got.text, opts.path);
    return { blob: got.blob ?? new Blob([]), headers: got.res.headers };
  }

  private async doFetch(opts: RequestOptions): Promise<RawResponse> {
    const { res, text } = await this.exchange(opts, false);
    if (!res.ok) throw this.failed(res, text, opts.path);
    return { status: res.status, headers: res.headers, text };
  }

  /** A non-2xx answer: the gateway's own failure, the family's vendor error, or an HTTP error in words. */
  private failed(res: AnswerHead, text: string, path: string): LinkError {
    const body = parseJsonLenient(text);
    const own = gatewayError(res, body);
    if (own) return own;
    const vendor = this.parseError?.(res.status, body === NOT_JSON ? null : body, text);
    if (vendor) return vendor;
    return httpError(res.status, path, text);
  }

  /**
   * One request and its whole answer, under one timeout: the body is read under the same timer
   * and abort as the headers (a controller that sends headers and then falls silent is a
   * timeout, not a request that never ends), and a body that breaks off is a `network` error (a
   * cut answer: a link problem), never a protocol error.
   *
   * A request sent with the `commandId` of a command being performed (commands.ts) carries what is
   * left of its deadline (`X-Shopdeck-Deadline`, the gateway aborts it then) and waits that long
   * (and a moment for the gateway's answer); it is given up with the command and never sent once
   * the deadline has passed. A file transfer is not held to the deadline.
   */
  private async exchange(
    opts: RequestOptions,
    binary: boolean,
  ): Promise<{ res: AnswerHead; text: string; blob: Blob | null }> {
    // Cancelled before it left (the session stopped while it waited its turn): never sent.
    if (opts.signal?.aborted) throw new LinkError('network', `Request to ${opts.path} cancelled`);
    const scope = opts.commandId ? commandScope(this.machineId, opts.commandId) : null;
    const headers: Record<string, string> = { ...this.extraHeaders?.(), ...opts.headers };
    let timeout = opts.timeoutMs ?? this.timeoutMs;
    let endTransfer: (() => void) | null = null;
    if (opts.commandId) headers['X-Shopdeck-Command'] = opts.commandId;
    if (scope) {
      if (scope.signal.aborted)
        throw new LinkError('timeout', `${opts.path} not sent: the command was not confirmed in time`);
      if (isTransfer(opts.body)) endTransfer = scope.transfer();
      else {
        const left = scope.remainingMs();
        if (left !== null) {
          if (left <= 0)
            throw new LinkError('timeout', `${opts.path} not sent: the command's deadline had passed`);
          const ms = Math.max(1, Math.ceil(left));
          headers['X-Shopdeck-Deadline'] = String(ms);
          timeout = Math.min(opts.timeoutMs ?? Number.POSITIVE_INFINITY, ms + DEADLINE_GRACE_MS);
        }
      }
    }
    const ctrl = new AbortController();
    let timedOut = false;
    const timer = setTimeout(() => {
      timedOut = true;
      ctrl.abort();
    }, timeout);
    const onAbort = () => ctrl.abort();
    opts.signal?.addEventListener('abort', onAbort);
    scope?.signal.addEventListener('abort', onAbort);
    let body: BodyInit | null | undefined = opts.body;
    if (opts.json !== undefined) {
      body = JSON.stringify(opts.json);
      headers['Content-Type'] = 'application/json';
    }
    const secs = `${Math.round(timeout / 100) / 10} s`;
    /** Why the exchange ended without a whole answer. */
    const failure = (e: unknown, phase: 'request' | 'body'): LinkError => {
      if (timedOut)
        return new LinkError(
          'timeout',
          phase === 'request'
            ? `No answer from ${opts.path} within ${secs}`
            : `The answer from ${opts.path} did not come whole within ${secs}`,
        );
      if (opts.signal?.aborted) return new LinkError('aborted', 'Request cancelled');
      if (scope?.signal.aborted)
        return new LinkError('timeout', `No confirmation from ${opts.path} in time: given up`);
      const why = e instanceof Error ? e.message : String(e);
      return phase === 'request'
        ? new LinkError('network', connectionLost(why))
        : new LinkError('network', `The answer from ${opts.path} was cut (${why})`);
    };
    this.inFlight++;
    this.maxInFlight = Math.max(this.maxInFlight, this.inFlight);
    try {
      // A plain read (no body, not a command, text) goes over the page's read socket while it is
      // open (read-socket.ts); anything it does not answer goes over HTTP below.
      const sock = binary || body || opts.commandId || (opts.method ?? 'GET') !== 'GET' ? null : readSocket();
      if (sock) {
        let asked: Promise<SocketAnswer | null> | null;
        try {
          asked = sock.read(this.url(opts.path, opts.query), { ...headers, ...CONSOLE_HEADERS }, ctrl.signal);
        } catch {
          asked = null;
        }
        if (asked) {
          let got: SocketAnswer | null;
          try {
            got = await asked;
          } catch (e) {
            throw failure(e, 'request');
          }
          if (got) {
            const ok = got.status >= 200 && got.status < 300;
            return { res: { status: got.status, ok, headers: got.headers }, text: got.text, blob: null };
          }
          if (ctrl.signal.aborted) throw failure(new Error('aborted'), 'request');
        }
      }
      let res: Response;
      try {
        res = await globalThis.fetch(this.url(opts.path, opts.query), {
          method: opts.method ?? 'GET',
          headers: { ...headers, ...CONSOLE_HEADERS },
          body: body ?? null,
          signal: ctrl.signal,
          credentials: 'same-origin',
        });
      } catch (e) {
        throw failure(e, 'request');
      }
      try {
        if (binary && res.ok) return { res, text: '', blob: await res.blob() };
        return { res, text: await res.text(), blob: null };
      } catch (e) {
        throw failure(e, 'body');
      }
    } finally {
      this.inFlight--;
      clearTimeout(timer);
      opts.signal?.removeEventListener('abort', onAbort);
      scope?.signal.removeEventListener('abort', onAbort);
      endTransfer?.();
    }
  }
}

export const NOT_JSON: unique symbol = Symbol('not-json');

/** A request body that is a file transfer (a file, a form, bytes), not a command's few words. */
function isTransfer(body: BodyInit | null | undefined): boolean {
  if (body === null || body === undefined || typeof body === 'string') return false;
  if (typeof URLSearchParams !== 'undefined' && body instanceof URLSearchParams) return false;
  return true;
}

/**
 * The console's own server marks its answers (`X-Shopdeck-Gateway: error`; a 5xx whose JSON body
 * says `gateway: true` is read the same way): it could not reach the controller, timed out, or
 * refused the request. Such an answer is never read as the controller's: no vendor error code, no
 * model or protocol verdict; its words are shown as they are. A 504 is a timeout; other 5xx a
 * network failure (a link problem); 4xx a refusal (`http`). `notConfirmed`: a command that may or
 * may not have reached the machine.
 */
export function gatewayError(res: Pick<Response, 'status' | 'headers'>, body: unknown): LinkError | null {
  return gatewayFailure(res.status, res.headers, body);
}

function gatewayFailure(status: number, headers: Headers, body: unknown): LinkError | null {
  const rec =
    typeof body === 'object' && body !== null && !Array.isArray(body)
      ? (body as Record<string, unknown>)
      : null;
  const marked = headers.get('x-shopdeck-gateway') === 'error';
  if (!marked && !(rec?.gateway === true && status >= 500)) return null;
  // The console's own 401: this page's session is gone (a controller's 401 is never marked).
  if (marked && status === 401) sessionGone();
  const said = rec && typeof rec.error === 'string' ? rec.error.trim() : '';
  const words =
    status === 401 && rec?.login === true
      ? signInWords(said)
      : said || `the console server answered HTTP ${status}`;
  const kind = status === 504 ? 'timeout' : status >= 500 ? 'network' : 'http';
  return new LinkError(kind, words.slice(0, 300), {
    status,
    fromGateway: true,
    notConfirmed: rec?.notConfirmed === true,
  });
}

/**
 * The console server's "sign in" answer (401 with `login: true`) in the words of the page's own
 * sign-in screen, not the server's terse API text ("log in first").
 */
export function signInWords(said: string): string {
  return /expired/i.test(said)
    ? 'Your sign-in has expired: sign in again to see this machine.'
    : 'You are not signed in: sign in to see this machine.';
}

/** A controller's HTTP error in words: its own message when its body has one, never a JSON dump. */
function httpError(status: number, path: string, text: string): LinkError {
  const words =
    wordsOf(text) ?? (text.trim().startsWith('{') || text.trim().startsWith('[') ? '' : preview(text));
  return new LinkError('http', `HTTP ${status} from ${path}${words ? `: ${preview(words)}` : ''}`, {
    status,
  });
}

export function parseJsonLenient(text: string): unknown {
  const t = text.trim();
  if (t === '') return NOT_JSON;
  try {
    return JSON.parse(t) as unknown;
  } catch {
    return NOT_JSON;
  }
}

export function preview(text: string, max = 120): string {
  const t = text.replace(/\s+/g, ' ').trim();
  return t.length > max ? `${t.slice(0, max)}…` : t;
}

export interface UploadProgress {
  loaded: number;
  total: number;
}

/**
 * Upload with progress events (fetch has none for request bodies). Uses XMLHttpRequest from
 * `globalThis` at call time so msw's interceptors see it. An upload sent for a command
 * (`X-Shopdeck-Command`) is a transfer: the command's deadline waits while it runs (its own
 * timeout applies). The gateway's own failures are told apart as in `HttpClient`.
 */
export function uploadWithProgress(opts: {
  method: 'POST' | 'PUT';
  url: string;
  body: XMLHttpRequestBodyInit;
  headers?: Record<string, string>;
  onProgress?: (p: UploadProgress) => void;
  signal?: AbortSignal;
  timeoutMs?: number;
}): Promise<RawResponse> {
  const commandId = Object.entries(opts.headers ?? {}).find(
    ([k]) => k.toLowerCase() === 'x-shopdeck-command',
  )?.[1];
  const machine = /\/machines\/([^/?#]+)/.exec(opts.url)?.[1];
  let machineId: string | null = null;
  try {
    machineId = machine ? decodeURIComponent(machine) : null;
  } catch {
    machineId = null;
  }
  const scope = commandId && machineId ? commandScope(machineId, commandId) : null;
  const endTransfer = scope?.transfer() ?? (() => undefined);
  const sent = new Promise<RawResponse>((resolve, reject) => {
    const Xhr = globalThis.XMLHttpRequest;
    const xhr = new Xhr();
    xhr.open(opts.method, opts.url);
    for (const [k, v] of Object.entries({ ...opts.headers, ...CONSOLE_HEADERS })) xhr.setRequestHeader(k, v);
    xhr.timeout = opts.timeoutMs ?? 120_000;
    xhr.upload.onprogress = (e) => opts.onProgress?.({ loaded: e.loaded, total: e.total });
    xhr.onload = () => {
      const headers = new Headers();
      for (const line of xhr
        .getAllResponseHeaders()
        .trim()
        .split(/[\r\n]+/)) {
        const i = line.indexOf(':');
        if (i > 0) headers.append(line.slice(0, i).trim(), line.slice(i + 1).trim());
      }
      const res = { status: xhr.status, headers, text: xhr.responseText };
      if (xhr.status >= 200 && xhr.status < 300) resolve(res);
      else
        reject(
          gatewayFailure(xhr.status, headers, parseJsonLenient(xhr.responseText)) ??
            httpError(xhr.status, 'upload', xhr.responseText),
        );
    };
    xhr.onerror = () => reject(new LinkError('network', 'Upload failed: cannot reach the controller'));
    xhr.ontimeout = () => reject(new LinkError('timeout', 'Upload timed out'));
    xhr.onabort = () => reject(new LinkError('aborted', 'Upload cancelled'));
    opts.signal?.addEventListener('abort', () => xhr.abort());
    xhr.send(opts.body);
  });
  return sent.finally(endTransfer);
}

/**
 * The words for a request that got no answer at all: the page could not reach the console server,
 * or the connection broke (the console server answers for the controller itself when it cannot
 * reach it: those words come from it). The browser's own "no connection" text ("Failed to fetch")
 * is left out; another reason is kept in brackets.
 */
export function connectionLost(why: string): string {
  const said = BROWSER_NETWORK_WORDS.test(why.trim()) ? '' : why.trim();
  return `No answer: the connection to the console server broke${said ? ` (${said})` : ''}`;
}

/**
 * What browsers say for "no connection" (Chrome, Firefox, Safari): nothing a person at the
 * machine can use, so it is left out; any other reason is kept in brackets.
 */
const BROWSER_NETWORK_WORDS =
  /^(Failed to fetch|NetworkError when attempting to fetch resource\.?|Load failed|Network request failed|The network connection was lost\.?)$/i;
