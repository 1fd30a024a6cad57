import type { IncomingMessage } from 'node:http';

/**
 * Proof that a request comes from the console's own page, not from another web site (an
 * `<img src>`, a form, a `fetch` from another origin or from another port of the same host, which
 * is the same *site* and so gets SameSite=Strict cookies).
 *
 * - `X-Shopdeck: 1`: a page of another origin cannot send a custom header without a CORS
 *   preflight, and the gateway never grants one. Required for every state-changing request:
 *   every non-GET/HEAD/OPTIONS request, and every GET a family marks as a command.
 * - `Sec-Fetch-Site` (sent by every current browser): must be `same-origin`, or `none` (the user
 *   typed or bookmarked the URL) for reads. `same-site` (another port of this host) and
 *   `cross-site` are refused for everything, reads included.
 * - `Origin`, when sent, must be this host (including its port); `null` (sandboxed frames,
 *   redirects across origins) is refused.
 * - WebSocket upgrades cannot carry a custom header: browsers always send `Origin` on them, so it
 *   is required and must match.
 */

export const CONSOLE_HEADER = 'x-shopdeck';

export type RequestKind =
  | 'read'
  /** A state-changing request: needs the console header. */
  | 'command'
  /** A WebSocket upgrade: needs a matching Origin. */
  | 'websocket';

function header(req: IncomingMessage, name: string): string | undefined {
  const v = req.headers[name];
  return Array.isArray(v) ? v[0] : v;
}

/** Why this request does not prove it comes from the console, or null when it does. */
export function crossSiteProblem(req: IncomingMessage, kind: RequestKind): string | null {
  const site = header(req, 'sec-fetch-site');
  if (site !== undefined) {
    const ok = site === 'same-origin' || (site === 'none' && kind === 'read');
    if (!ok) return `a request from another site (Sec-Fetch-Site: ${site.slice(0, 20)})`;
  }
  const origin = header(req, 'origin');
  if (origin !== undefined) {
    if (origin === 'null') return 'a request from an opaque origin';
    let host: string;
    try {
      host = new URL(origin).host;
    } catch {
      return 'a request with a malformed Origin';
    }
    if (host !== req.headers.host) return 'a request from another origin';
  } else if (kind === 'websocket') {
    return 'a WebSocket without an Origin';
  }
  if (kind === 'command' && header(req, CONSOLE_HEADER) !== '1')
    return 'a command without the console header (X-Shopdeck)';
  return null;
}
