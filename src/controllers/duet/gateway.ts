import type { HeldSessionHooks, UpstreamAnswer } from '../../fleet/contract';

/**
 * The gateway holds the DSF session (gateway/held-session.ts): a session key lets whoever has it
 * send any G-code (M112) straight to the printer, around every role check, so no browser ever
 * gets one. Node-safe and pure: the gateway imports it through `family.ts`.
 *
 * - `GET /machine/connect?password=` from a browser is answered by the gateway: the connect
 *   answer of the gateway's own session without `sessionKey` (a wrong password typed into the
 *   login form gets DSF's 403 as it is); `GET /machine/disconnect` is answered with 204 and
 *   leaves the shared session alone.
 * - `X-Session-Key` (HTTP) and `sessionKey` (the socket URL) are the gateway's; whatever the
 *   browser sent under those names (in any letter case: ASP.NET does not care) is dropped.
 * - 403 means the key expired or is unknown (DSF forgets a session 8 s after its last request
 *   unless a socket is open): `GET /machine/noop` every 4 s keeps it while it is in use.
 */

const SESSION_HEADER = 'x-session-key';
const SESSION_PARAM = 'sessionkey';

/**
 * A path as ASP.NET routes it: segments percent-decoded, matched in any letter case, empty
 * segments and a trailing slash ignored ("/Machine//Connect/" is "/machine/connect"). An
 * undecodable segment stays as it is (Kestrel leaves it too).
 */
export function routeOf(path: string): string {
  const segs: string[] = [];
  for (const s of (path.split('?')[0] ?? '').split('/')) {
    if (s === '') continue;
    let d = s;
    try {
      d = decodeURIComponent(s);
    } catch {
      // kept as is
    }
    segs.push(d.toLowerCase());
  }
  return `/${segs.join('/')}`;
}

/** A query parameter as ASP.NET model binding reads it (name in any letter case, first value). */
function paramOf(query: URLSearchParams, name: string): string | null {
  for (const [k, v] of query) if (k.toLowerCase() === name) return v;
  return null;
}

function dropKey(req: { headers: Record<string, string>; query: URLSearchParams }): void {
  for (const k of Object.keys(req.headers)) if (k.toLowerCase() === SESSION_HEADER) delete req.headers[k];
  for (const k of [...new Set(req.query.keys())]) if (k.toLowerCase() === SESSION_PARAM) req.query.delete(k);
}

/** The connect answer for browsers: every field but the key (`sessionKey`, any letter case). */
export function withoutSessionKey(body: string): string {
  let parsed: unknown;
  try {
    parsed = JSON.parse(body);
  } catch {
    return '{}';
  }
  if (typeof parsed !== 'object' || parsed === null || Array.isArray(parsed)) return '{}';
  const out: Record<string, unknown> = {};
  for (const [k, v] of Object.entries(parsed as Record<string, unknown>))
    if (k.toLowerCase() !== SESSION_PARAM) out[k] = v;
  return JSON.stringify(out);
}

/** The key of a connect answer (a string, or a number on some versions), or null. */
export function sessionKeyOf(body: string): string | null {
  try {
    const parsed: unknown = JSON.parse(body);
    if (typeof parsed !== 'object' || parsed === null) return null;
    for (const [k, v] of Object.entries(parsed as Record<string, unknown>)) {
      if (k.toLowerCase() !== SESSION_PARAM) continue;
      if (typeof v === 'string' && v !== '') return v;
      if (typeof v === 'number' && Number.isFinite(v)) return String(v);
    }
  } catch {
    // not JSON: no key
  }
  return null;
}

export const duetHeldSession: HeldSessionHooks = {
  intercept(req) {
    // Every method: no browser request may reach DSF's connect (it would mint a key the gateway
    // does not know) or its disconnect (it would carry the gateway's key and end its session).
    const r = routeOf(req.path);
    if (r === '/machine/connect') {
      const password = paramOf(req.query, 'password');
      return password === null ? { kind: 'open' } : { kind: 'open', credentials: { password } };
    }
    if (r === '/machine/disconnect') return { kind: 'close' };
    return null;
  },

  async open(upstream, credentials) {
    const password = credentials?.password;
    const q = password !== undefined ? `?${new URLSearchParams({ password }).toString()}` : '';
    const r = await upstream('GET', `/machine/connect${q}`);
    if (r.status !== 200) return { ok: false, answer: r };
    const answer: UpstreamAnswer = {
      status: 200,
      headers: { 'content-type': 'application/json' },
      body: withoutSessionKey(r.body),
    };
    return { ok: true, key: sessionKeyOf(r.body), answer };
  },

  async close(upstream, key) {
    await upstream('GET', '/machine/disconnect', { 'X-Session-Key': key });
  },

  apply(req, key) {
    dropKey(req);
    if (key !== null) req.headers[SESSION_HEADER] = key;
  },

  applyWs(req, key) {
    dropKey(req);
    if (key !== null) req.query.set('sessionKey', key);
  },

  isExpired: (status) => status === 403,

  keepAlive: { path: '/machine/noop', everyMs: 4000, whileUsedWithinMs: 60_000 },
};
