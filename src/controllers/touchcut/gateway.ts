import type { HeldCredentials, HeldSessionHooks, UpstreamAnswer } from '../../fleet/contract';
import { touchcutResource } from './access';
import { authResponseSchema } from './wire';

/**
 * The gateway holds the TouchCut user login (gateway/held-session.ts): a JWT lets whoever has it
 * read the machine with that user's privileges and change the user's password, around every role
 * of the console, so no browser ever gets one. Node-safe and pure: the gateway imports it through
 * `declaration.ts` (so does the browser, which uses only the types and `LOGIN_PATH`).
 *
 * - `POST rest/v1/auth` (username, password: form or JSON body) from a browser is performed by
 *   the gateway; the JWT stays there, shared by every viewer of the machine, and the browser gets
 *   `HeldLogin`: TouchCut's answer without the token, plus the user and the token's expiry.
 * - `GET rest/v1/auth` (TouchCut has no such request: 405) is answered by the gateway with the
 *   current `HeldLogin`; `DELETE rest/v1/auth` logs the shared login out (answered 204 locally:
 *   TouchCut has no logout, a JWT simply lapses).
 * - `POST rest/v1/auth/change-password` is sent by the gateway with its JWT; the new JWT in
 *   TouchCut's answer replaces the held one and is taken out of the answer.
 * - Any other method or sub-path of `auth` (`auth/x`, `auth;x`, `authx`) is answered 405 here:
 *   nothing a browser sends can make TouchCut mint a token that the gateway does not hold.
 * - Every forwarded request: `Authorization`, cookies (`__Secure-jwt`) and `X-TouchCut-API-Key`
 *   the browser sent are dropped; the held JWT is added as `Authorization: Bearer`. Without one,
 *   the declaration's `injectSecrets` adds the machine's API key as before (`takesApiKey`).
 * - A 401 answered to the held JWT (expired or revoked) drops it (`expiry: 'forget'`): the browser
 *   gets the 401 and asks for a login again; the typed password was never kept. A 401 of
 *   `auth/change-password` is not taken as expiry: TouchCut also answers 401 there to a user
 *   without the privilege (the next status read tells).
 */

/** The TouchCut login resource, as the browser's client calls it. */
export const LOGIN_PATH = '/rest/v1/auth';

/** What the gateway answers about the held login: never the token. */
export interface HeldLogin {
  /** TouchCut's own `success` ("true") after a login or password change. */
  success?: string;
  loggedIn: boolean;
  /** The TouchCut user name as typed at login. */
  user: string | null;
  /** The JWT's `exp` (ms since epoch), display only; null when unknown. */
  expiresAt: number | null;
}

/** Reads `exp` of a JWT (the token is untrusted: any failure gives null). */
export function jwtExpiry(token: string): number | null {
  try {
    const part = token.split('.')[1];
    if (!part) return null;
    const json = atob(part.replace(/-/g, '+').replace(/_/g, '/') + '==='.slice((part.length + 3) % 4));
    const exp = (JSON.parse(json) as { exp?: unknown }).exp;
    return typeof exp === 'number' && Number.isFinite(exp) ? exp * 1000 : null;
  } catch {
    return null;
  }
}

function objectOf(body: string): Record<string, unknown> | null {
  try {
    const parsed: unknown = JSON.parse(body);
    return typeof parsed === 'object' && parsed !== null && !Array.isArray(parsed)
      ? (parsed as Record<string, unknown>)
      : null;
  } catch {
    return null;
  }
}

const isTokenField = (k: string): boolean => /^(token|jwt)$/i.test(k);

/** The token of an auth answer (`{ "success": "true", "token": "<JWT>" }`, wire.ts), or null. */
export function tokenOf(body: string): string | null {
  const r = authResponseSchema.safeParse(objectOf(body));
  return r.success && r.data.success !== false ? r.data.token : null;
}

/** Every field of a JSON object answer but the token; other bodies (empty, text) as they are. */
export function withoutToken(body: string): string {
  const o = objectOf(body);
  if (!o) return body;
  // Own keys kept as data (fromEntries defines them: a `__proto__` key is not a prototype).
  return JSON.stringify(Object.fromEntries(Object.entries(o).filter(([k]) => !isTokenField(k))));
}

function json(status: number, body: unknown): UpstreamAnswer {
  return {
    status,
    headers: { 'content-type': 'application/json; charset=utf-8' },
    body: JSON.stringify(body),
  };
}

/** The login answer for browsers: TouchCut's fields without the token, the user and the expiry. */
function loginAnswer(controllerBody: string, user: string | null, token: string): UpstreamAnswer {
  const fields = objectOf(withoutToken(controllerBody)) ?? {};
  const held: HeldLogin = {
    ...(typeof fields.success === 'string' ? { success: fields.success } : {}),
    loggedIn: true,
    user,
    expiresAt: jwtExpiry(token),
  };
  return json(200, { ...fields, ...held });
}

const NOT_LOGGED_IN: HeldLogin = { loggedIn: false, user: null, expiresAt: null };

/** The answer to a request of `auth` that TouchCut does not have (its own 405). */
const NOT_ALLOWED: UpstreamAnswer = { status: 405, headers: {}, body: '' };

/**
 * The login's credentials from a browser's body: a form (what the console sends) or JSON.
 * Missing fields are empty: TouchCut itself answers "Required parameter missing" (1003).
 */
export function credentialsOf(body: string, contentType: string): HeldCredentials {
  let username = '';
  let password = '';
  if (/json/i.test(contentType) || body.trim().startsWith('{')) {
    const o = objectOf(body) ?? {};
    if (typeof o.username === 'string') username = o.username;
    if (typeof o.password === 'string') password = o.password;
  } else {
    const form = new URLSearchParams(body);
    username = form.get('username') ?? '';
    password = form.get('password') ?? '';
  }
  return { username, password };
}

/** Every credential a browser could send TouchCut (the manual: Bearer, the cookie, the key). */
const BROWSER_CREDENTIALS = new Set(['authorization', 'cookie', 'x-touchcut-api-key']);

function applyKey(req: { headers: Record<string, string> }, key: string | null): void {
  for (const k of Object.keys(req.headers))
    if (BROWSER_CREDENTIALS.has(k.toLowerCase())) delete req.headers[k];
  if (key !== null) req.headers.Authorization = `Bearer ${key}`;
}

/** The user name of the held login (the session's answer). */
function userOf(session: UpstreamAnswer | null): string | null {
  const u = session ? objectOf(session.body)?.user : undefined;
  return typeof u === 'string' ? u : null;
}

export const touchcutHeldSession: HeldSessionHooks = {
  intercept(req) {
    const r = touchcutResource(req.path);
    // `auth` in any spelling TouchCut's server might route to it (`auth;x`, `auth.json`, `authx`).
    if (r === null || !r.startsWith('auth')) return null;
    const method = req.method.toUpperCase();
    if (r === 'auth') {
      if (method === 'POST') return { kind: 'open', fromBody: credentialsOf };
      if (method === 'GET' || method === 'HEAD') return { kind: 'open' };
      if (method === 'DELETE') return { kind: 'close', end: true };
    }
    if (r === 'auth/change-password' && method === 'POST') return { kind: 'exchange' };
    return { kind: 'answer', answer: NOT_ALLOWED };
  },

  // The machines file's `apiKey` is no login: `injectSecrets` adds it where no JWT is held.
  configured: () => undefined,

  async open(upstream, credentials) {
    if (credentials?.username === undefined) return { ok: true, key: null, answer: json(200, NOT_LOGGED_IN) };
    const form = new URLSearchParams({ username: credentials.username, password: credentials.password });
    const r = await upstream(
      'POST',
      LOGIN_PATH,
      { 'content-type': 'application/x-www-form-urlencoded', accept: 'application/json' },
      form.toString(),
    );
    const token = r.status === 200 ? tokenOf(r.body) : null;
    // Refused (or a 200 without a token: an error body sent with the wrong status): as it is.
    if (token === null) return { ok: false, answer: { ...r, body: withoutToken(r.body) } };
    return { ok: true, key: token, answer: loginAnswer(r.body, credentials.username, token) };
  },

  apply: applyKey,
  applyWs: applyKey,

  isExpired: (status, req) =>
    status === 401 && (req === undefined || touchcutResource(req.path) !== 'auth/change-password'),

  expiry: 'forget',

  exchanged(answer, session) {
    const token = answer.status === 200 ? tokenOf(answer.body) : null;
    if (token === null) return { key: null, answer: { ...answer, body: withoutToken(answer.body) } };
    return { key: token, answer: loginAnswer(answer.body, userOf(session), token) };
  },
};
