import type { IncomingHttpHeaders, IncomingMessage, ServerResponse } from 'node:http';
import type { Duplex } from 'node:stream';

/** Small helpers for the gateway's own answers and for header hygiene. */

export function sendJson(
  res: ServerResponse,
  status: number,
  body: unknown,
  headers: Record<string, string> = {},
): void {
  sendJsonText(res, status, JSON.stringify(body), headers);
}

/** `sendJson` of a JSON text already made (e.g. by a history read worker). */
export function sendJsonText(
  res: ServerResponse,
  status: number,
  text: string,
  headers: Record<string, string> = {},
): void {
  res.writeHead(status, {
    // The gateway's own refusals and failures say so: the page never reads them as the controller's.
    ...(status >= 400 ? { 'X-Shopdeck-Gateway': 'error' } : {}),
    'Content-Type': 'application/json; charset=utf-8',
    'Content-Length': Buffer.byteLength(text),
    'Cache-Control': 'no-store',
    'X-Content-Type-Options': 'nosniff',
    ...headers,
  });
  res.end(text);
}

/** Answers a refused WebSocket upgrade on the raw socket with a JSON body, then closes it. */
export function rejectUpgrade(socket: Duplex, status: number, body: unknown): void {
  const text = JSON.stringify(body);
  const reason: Record<number, string> = {
    400: 'Bad Request',
    401: 'Unauthorized',
    403: 'Forbidden',
    404: 'Not Found',
    502: 'Bad Gateway',
    503: 'Service Unavailable',
    504: 'Gateway Timeout',
  };
  if (socket.writable) {
    socket.write(
      `HTTP/1.1 ${status} ${reason[status] ?? 'Error'}\r\n` +
        'Connection: close\r\n' +
        // The gateway's own refusal, as every one of its failures says (sendJson).
        'X-Shopdeck-Gateway: error\r\n' +
        'Content-Type: application/json; charset=utf-8\r\n' +
        `Content-Length: ${Buffer.byteLength(text)}\r\n` +
        '\r\n' +
        text,
    );
  }
  socket.destroy();
}

/**
 * A command's deadline as the console sends it (`X-Shopdeck-Deadline: <ms>`, the time left until
 * the operator is told "not confirmed"). Never longer than this, whatever a page asks.
 */
export const MAX_COMMAND_DEADLINE_MS = 120_000;

/**
 * The deadline of a command in ms: the browser's `X-Shopdeck-Deadline` when it is a positive whole
 * number (capped at `MAX_COMMAND_DEADLINE_MS`), else `fallback` (also capped; null: none).
 */
export function commandDeadlineMs(
  value: string | string[] | undefined,
  fallback: number | null,
): number | null {
  const raw = Array.isArray(value) ? value[0] : value;
  const ms = raw !== undefined && /^\s*\d{1,12}\s*$/.test(raw) ? Number(raw) : NaN;
  const chosen = Number.isFinite(ms) && ms > 0 ? ms : fallback;
  return chosen === null ? null : Math.min(chosen, MAX_COMMAND_DEADLINE_MS);
}

/** "0.3 s", "5 s", "12.5 s": a duration as operators read it. */
export function secondsWords(ms: number): string {
  const s = Math.round(ms / 100) / 10;
  return `${s} s`;
}

export class BodyTooLarge extends Error {
  constructor(readonly limit: number) {
    super(`request body larger than ${limit} bytes`);
  }
}

const streamedBodies = new WeakSet<IncomingMessage>();

/**
 * The gateway passes this request's body on as it arrives (an upload streamed to a controller or
 * a simulator): the server's body deadline (server/body-deadline.ts) then bounds its stalls, not
 * its length in time.
 */
export function markStreamedBody(req: IncomingMessage): void {
  streamedBodies.add(req);
}

export function isStreamedBody(req: IncomingMessage): boolean {
  return streamedBodies.has(req);
}

/** Reads a request body into memory, refusing more than `limit` bytes. */
export function readBody(req: IncomingMessage, limit: number): Promise<Buffer> {
  return new Promise((resolve, reject) => {
    const chunks: Buffer[] = [];
    let size = 0;
    let failed = false;
    req.on('data', (c: Buffer) => {
      if (failed) return;
      size += c.length;
      if (size > limit) {
        failed = true;
        reject(new BodyTooLarge(limit));
        req.resume();
        return;
      }
      chunks.push(c);
    });
    req.on('end', () => {
      if (!failed) resolve(Buffer.concat(chunks));
    });
    req.on('error', (e) => {
      if (!failed) reject(e);
    });
  });
}

export async function readJson(req: IncomingMessage, limit = 16 * 1024): Promise<unknown> {
  const buf = await readBody(req, limit);
  if (buf.length === 0) return {};
  return JSON.parse(buf.toString('utf8')) as unknown;
}

/** Headers that describe one hop, not the message (RFC 9110 §7.6.1), plus those named in Connection. */
const HOP_BY_HOP = new Set([
  'connection',
  'keep-alive',
  'proxy-authenticate',
  'proxy-authorization',
  'proxy-connection',
  'te',
  'trailer',
  'transfer-encoding',
  'upgrade',
  'host',
  'content-length',
]);

const METHOD_OVERRIDE = new Set(['x-http-method-override', 'x-http-method', 'x-method-override']);

function connectionTokens(headers: IncomingHttpHeaders): Set<string> {
  const c = headers.connection;
  const s = new Set<string>();
  if (typeof c === 'string') for (const t of c.split(',')) s.add(t.trim().toLowerCase());
  return s;
}

/**
 * Headers forwarded to a controller: no hop-by-hop headers, no cookies (the console's session
 * cookie stays here), no `X-Shopdeck-*`, no Origin/Referer (controllers such as DSF refuse
 * foreign origins), no Accept-Encoding (so that answers can be checked for secrets). An
 * Authorization header passes: it is the controller's own login (TouchCut's JWT), not ours.
 */
export function forwardRequestHeaders(headers: IncomingHttpHeaders): Record<string, string> {
  const out: Record<string, string> = {};
  const conn = connectionTokens(headers);
  for (const [k, v] of Object.entries(headers)) {
    const key = k.toLowerCase();
    if (v === undefined) continue;
    if (HOP_BY_HOP.has(key) || conn.has(key)) continue;
    if (key === 'cookie' || key === 'x-shopdeck' || key.startsWith('x-shopdeck-')) continue;
    // A controller's framework may honour these and run another method than the one classified.
    if (METHOD_OVERRIDE.has(key)) continue;
    if (key === 'origin' || key === 'referer' || key === 'accept-encoding') continue;
    if (key.startsWith('sec-websocket-') || key.startsWith('x-forwarded-') || key === 'forwarded') continue;
    out[key] = Array.isArray(v) ? v.join(', ') : v;
  }
  return out;
}

/**
 * Headers of a controller's answer passed to the browser: no hop-by-hop headers, no
 * Set-Cookie (the controller's session is the gateway's business), no WWW-Authenticate (it
 * would pop up the browser's own password dialog).
 */
export function forwardResponseHeaders(headers: IncomingHttpHeaders): Record<string, string | string[]> {
  const out: Record<string, string | string[]> = {};
  const conn = connectionTokens(headers);
  for (const [k, v] of Object.entries(headers)) {
    const key = k.toLowerCase();
    if (v === undefined) continue;
    if (HOP_BY_HOP.has(key) || conn.has(key)) continue;
    if (key === 'set-cookie' || key === 'www-authenticate' || key === 'proxy-authenticate') continue;
    out[key] = v;
  }
  return out;
}

export function clientAddress(req: IncomingMessage): string {
  return req.socket.remoteAddress ?? 'unknown';
}

/**
 * Cross-site request check for state-changing requests and WebSocket upgrades: when the browser
 * sends an Origin, its host must be the host the request was sent to.
 */
export function sameOrigin(req: IncomingMessage): boolean {
  const origin = req.headers.origin;
  if (!origin || origin === 'null') return origin !== 'null';
  try {
    return new URL(origin).host === req.headers.host;
  } catch {
    return false;
  }
}

export function parseCookies(header: string | undefined): Record<string, string> {
  const out: Record<string, string> = {};
  if (!header) return out;
  for (const part of header.split(';')) {
    const i = part.indexOf('=');
    if (i < 0) continue;
    const k = part.slice(0, i).trim();
    const v = part.slice(i + 1).trim();
    if (k && !(k in out)) {
      try {
        out[k] = decodeURIComponent(v);
      } catch {
        out[k] = v;
      }
    }
  }
  return out;
}

/** A URL path segment decoded, or '' when it is not valid percent-encoding (then it names nothing). */
export function decodeSegment(raw: string): string {
  try {
    return decodeURIComponent(raw);
  } catch {
    return '';
  }
}
