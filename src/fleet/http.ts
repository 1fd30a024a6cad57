import type { z } from 'zod';
import { LinkError, protocolError } from './errors';
import { CONSOLE_HEADERS, machineBase } from './origin';

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
  /** Set for machine commands: sent as `X-Shopdeck-Command` for the audit log. */
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
  async json<S extends z.ZodType>(opts: RequestOptions, schema: S): Promise<z.output<S>> {
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
    const res = await this.fetchResponse(opts);
    if (!res.ok) {
      const text = await res.text();
      const body = parseJsonLenient(text);
      const own = gatewayError(res, body);
      if (own) throw own;
      const vendor = this.parseError?.(res.status, body === NOT_JSON ? null : body, text);
      if (vendor) throw vendor;
      throw new LinkError('http', `HTTP ${res.status} from ${opts.path}${text ? `: ${preview(text)}` : ''}`, {
        status: res.status,
      });
    }
    return { blob: await res.blob(), headers: res.headers };
  }

  private async doFetch(opts: RequestOptions): Promise<RawResponse> {
    const res = await this.fetchResponse(opts);
    const text = await res.text();
    if (!res.ok) {
      const body = parseJsonLenient(text);
      const own = gatewayError(res, body);
      if (own) throw own;
      const vendor = this.parseError?.(res.status, body === NOT_JSON ? null : body, text);
      if (vendor) throw vendor;
      throw new LinkError('http', `HTTP ${res.status} from ${opts.path}${text ? `: ${preview(text)}` : ''}`, {
        status: res.status,
      });
    }
    return { status: res.status, headers: res.headers, text };
  }

  private async fetchResponse(opts: RequestOptions): Promise<Response> {
    // Cancelled before it left (the session stopped while it waited its turn): never sent.
    if (opts.signal?.aborted) throw new LinkError('network', `Request to ${opts.path} cancelled`);
    const ctrl = new AbortController();
    const timeout = opts.timeoutMs ?? this.timeoutMs;
    let timedOut = false;
    const timer = setTimeout(() => {
      timedOut = true;
      ctrl.abort();
    }, timeout);
    const onAbort = () => ctrl.abort();
    opts.signal?.addEventListener('abort', onAbort);
    const headers: Record<string, string> = { ...this.extraHeaders?.(), ...opts.headers };
    if (opts.commandId) headers['X-Shopdeck-Command'] = opts.commandId;
    let body: BodyInit | null | undefined = opts.body;
    if (opts.json !== undefined) {
      body = JSON.stringify(opts.json);
      headers['Content-Type'] = 'application/json';
    }
    this.inFlight++;
    this.maxInFlight = Math.max(this.maxInFlight, this.inFlight);
    try {
      return await globalThis.fetch(this.url(opts.path, opts.query), {
        method: opts.method ?? 'GET',
        headers: { ...headers, ...CONSOLE_HEADERS },
        body: body ?? null,
        signal: ctrl.signal,
        credentials: 'same-origin',
      });
    } catch (e) {
      if (timedOut) throw new LinkError('timeout', `No answer from ${opts.path} within ${timeout / 1000} s`);
      if (opts.signal?.aborted) throw new LinkError('aborted', 'Request cancelled');
      throw new LinkError(
        'network',
        `Cannot reach the controller (${e instanceof Error ? e.message : String(e)})`,
      );
    } finally {
      this.inFlight--;
      clearTimeout(timer);
      opts.signal?.removeEventListener('abort', onAbort);
    }
  }
}

export const NOT_JSON: unique symbol = Symbol('not-json');

/**
 * The console's own server marks its answers (`X-Shopdeck-Gateway: error`): it could not reach the
 * controller, or refused the request. Such an answer is never read as the controller's: no vendor
 * error code, no model verdict; its words are shown as they are.
 */
export function gatewayError(res: Response, body: unknown): LinkError | null {
  if (res.headers.get('x-shopdeck-gateway') !== 'error') return null;
  const words =
    typeof body === 'object' && body !== null && typeof (body as { error?: unknown }).error === 'string'
      ? (body as { error: string }).error
      : `the console server answered HTTP ${res.status}`;
  return new LinkError(res.status >= 500 ? 'network' : 'http', words.slice(0, 300), {
    status: res.status,
    gateway: true,
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
 * `globalThis` at call time so msw's interceptors see it.
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
  return new Promise((resolve, reject) => {
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
          new LinkError(
            'http',
            `HTTP ${xhr.status} from upload${xhr.responseText ? `: ${preview(xhr.responseText)}` : ''}`,
            {
              status: xhr.status,
            },
          ),
        );
    };
    xhr.onerror = () => reject(new LinkError('network', 'Upload failed: cannot reach the controller'));
    xhr.ontimeout = () => reject(new LinkError('timeout', 'Upload timed out'));
    xhr.onabort = () => reject(new LinkError('aborted', 'Upload cancelled'));
    opts.signal?.addEventListener('abort', () => xhr.abort());
    xhr.send(opts.body);
  });
}
