import type { HeldSend, HeldSessionHooks, UpstreamAnswer } from '../../fleet/contract';
import { JobScanner, startedJobFiles } from './jobscan';
import { RrfReplies } from './replies';

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

/** Which API a Duet speaks: DSF (`/machine/*`, an SBC) or standalone RepRapFirmware (`rr_*`). */
export type DuetApi = 'dsf' | 'standalone';

/** `GET /machine/*` or `GET /rr_*`: both sessions' connect and disconnect are the gateway's. */
function connectRoute(r: string): 'connect' | 'disconnect' | null {
  if (r === '/machine/connect' || r === '/rr_connect') return 'connect';
  if (r === '/machine/disconnect' || r === '/rr_disconnect') return 'disconnect';
  return null;
}

/** RRF's `time=`: the local time, ISO without a zone (`HttpResponder.cpp` sets the clock from it). */
export function rrfTime(d: Date): string {
  const p = (n: number) => String(n).padStart(2, '0');
  return `${d.getFullYear()}-${p(d.getMonth() + 1)}-${p(d.getDate())}T${p(d.getHours())}:${p(d.getMinutes())}:${p(d.getSeconds())}`;
}

/** An `rr_connect` answer: `{err, sessionTimeout, boardType, apiLevel, sessionKey, isEmulated}`. */
export interface RrConnectAnswer {
  err: number;
  isEmulated: boolean;
  key: string | null;
  /** The answer without `sessionKey`, for browsers. */
  body: string;
}

export function readRrConnect(status: number, body: string): RrConnectAnswer | null {
  if (status !== 200) return null;
  let parsed: unknown;
  try {
    parsed = JSON.parse(body);
  } catch {
    return null;
  }
  if (typeof parsed !== 'object' || parsed === null || Array.isArray(parsed)) return null;
  const o = parsed as Record<string, unknown>;
  const err = o['err'];
  if (typeof err !== 'number') return null;
  return {
    err,
    isEmulated: o['isEmulated'] === true,
    key: sessionKeyOf(body),
    body: withoutSessionKey(body),
  };
}

const json = (status: number, body: string): UpstreamAnswer => ({
  status,
  headers: { 'content-type': 'application/json' },
  body,
});

/** A request of the standalone API (`/rr_model`, `/rr_gcode`, …). */
export const isRrPath = (path: string): boolean => routeOf(path).startsWith('/rr_');

/**
 * The session hooks of ONE Duet (`forMachine`): which API it speaks is learned when the session
 * is opened (or forced by the machines file's `"api"`), and then decides the keep-alive, the
 * disconnect and how an expired key shows.
 *
 * The probe follows Duet Web Control (`connector/index.ts`): `rr_connect` first; an answer with
 * `err` and without `isEmulated` is a standalone board; `isEmulated: true` (DSF ≥ 3.5 emulating
 * `rr_*`: its emulated session is closed at once), no JSON, or a 404 means DSF, and
 * `/machine/connect` follows. Once learned, the API stays for the gateway's life (a board does not
 * grow an SBC while it runs).
 *
 * Standalone: `rr_connect?password=&time=&sessionKey=yes`; `err` 1 (bad password) is answered to
 * the browser as 403 and `err` 2 (no free session: RRF has 8) as 503, both with RRF's body, so the
 * page reads them as DSF's refusals; `err` 0 is answered with the connect answer minus
 * `sessionKey` (its numeric `err` is how the page knows the board is standalone). The key goes in
 * `X-Session-Key`; 401 means it expired (RRF forgets a session after 8 s of silence: the
 * keep-alive `rr_model?key=seqs` every 4 s); `rr_disconnect` ends it.
 */
/** What one machine's hooks learned: its API (null until the first session is opened). */
export interface DuetApiState {
  api: DuetApi | null;
}

export function duetHeldSessionFor(
  state: DuetApiState,
  base: HeldSessionHooks = duetHeldSession,
): HeldSessionHooks {
  const learn = (a: DuetApi) => {
    state.api = a;
  };
  const replies = new RrfReplies();
  const hooks: HeldSessionHooks = {
    ...base,
    /**
     * Besides connect and disconnect: every `rr_reply` (any method, any spelling, with or without
     * a query) is the gateway's, never the board's (`replies.ts`: RRF's one reply buffer is used
     * up by whoever asks first); `GET rr_gcode` is sent by the gateway, whose answer carries the
     * ticket of its reply. A DSF board (whose `rr_*` emulation is not used) gets neither.
     */
    intercept(req) {
      const r = routeOf(req.path);
      if (r === '/rr_reply')
        return {
          kind: 'relay',
          run: async (send) => {
            if (state.api === null) await replies.sync(send).catch(() => undefined);
            return state.api === 'dsf'
              ? json(404, JSON.stringify({ error: 'rr_reply is not used with DSF' }))
              : replies.ask(send, req.query);
          },
        };
      const method = req.method.toUpperCase();
      // A job start by anyone but a supervisor: the file is read and checked first (jobscan.ts).
      const code =
        r === '/rr_gcode' && method === 'GET'
          ? [...req.query]
              .filter(([k]) => k.toLowerCase() === 'gcode')
              .map(([, v]) => v)
              .join('\n')
          : r === '/machine/code' && method === 'POST'
            ? (req.body ?? '')
            : '';
      const files = code ? startedJobFiles(code) : [];
      const forward = (send: HeldSend): Promise<UpstreamAnswer> =>
        r === '/machine/code'
          ? send('POST', req.path, req.query, { body: req.body ?? '' })
          : replies.code(send, req.query);
      if (files.length > 0 && req.role !== 'supervisor')
        return {
          kind: 'relay',
          run: async (send) => {
            for (const f of files) {
              const refused = await checkJobFile(send, f, r === '/rr_gcode');
              if (refused) return refused;
            }
            return forward(send);
          },
        };
      if (r === '/rr_gcode' && method === 'GET' && state.api !== 'dsf')
        return { kind: 'relay', run: (send) => replies.code(send, req.query) };
      return base.intercept(req);
    },
    async open(upstream, credentials) {
      if (state.api !== 'dsf') {
        const q = new URLSearchParams({
          password: credentials?.password ?? '',
          time: rrfTime(new Date()),
          sessionKey: 'yes',
        });
        const r = await upstream('GET', `/rr_connect?${q.toString()}`);
        const a = readRrConnect(r.status, r.body);
        if (a && !a.isEmulated) {
          learn('standalone');
          if (a.err === 1) return { ok: false, answer: json(403, a.body) };
          if (a.err !== 0) return { ok: false, answer: json(503, a.body) };
          return { ok: true, key: a.key, answer: json(200, a.body) };
        }
        if (a?.isEmulated && a.key !== null)
          await upstream('GET', '/rr_disconnect', { 'X-Session-Key': a.key });
        if (state.api === 'standalone') return { ok: false, answer: r };
        if (a?.isEmulated) learn('dsf');
      }
      const r = await base.open(upstream, credentials);
      if (r.ok) learn('dsf');
      return r;
    },
    async close(upstream, key) {
      if (state.api === 'standalone') await upstream('GET', '/rr_disconnect', { 'X-Session-Key': key });
      else await base.close?.(upstream, key);
    },
    isExpired: (status, req) =>
      state.api === 'standalone' || (req !== undefined && isRrPath(req.path))
        ? status === 401 || status === 403
        : base.isExpired(status, req),
    get keepAlive() {
      return state.api === 'standalone'
        ? { path: '/rr_model?key=seqs&flags=d99vno', everyMs: 4000, whileUsedWithinMs: 60_000 }
        : base.keepAlive;
    },
  };
  return hooks;
}

/**
 * Reads a job file from the board as it streams and checks what an operator's job may contain
 * (`jobscan.ts`): null when it may be started, else the refusal for the browser (403, naming the
 * file, the line and the code). A file that cannot be read is refused too: never started unchecked.
 */
async function checkJobFile(
  send: HeldSend,
  file: string,
  standalone: boolean,
): Promise<UpstreamAnswer | null> {
  const scanner = new JobScanner();
  const refuse = (why: string): UpstreamAnswer =>
    json(
      403,
      JSON.stringify({
        error: `refused: ${file}: ${why}; an operator may not start this file (a supervisor may)`,
        gateway: true,
      }),
    );
  let a: UpstreamAnswer;
  try {
    a = standalone
      ? await send('GET', '/rr_download', new URLSearchParams({ name: file }), {
          onData: (c) => scanner.push(c),
        })
      : await send('GET', `/machine/file/${encodeURIComponent(file)}`, undefined, {
          onData: (c) => scanner.push(c),
        });
  } catch (e) {
    return refuse(`the file could not be read to check it (${e instanceof Error ? e.message : String(e)})`);
  }
  if (a.status !== 200) return refuse(`the file could not be read to check it (HTTP ${a.status})`);
  const f = scanner.end();
  if (!f) return null;
  return refuse(`line ${f.line}${f.code ? `: ${f.code} ${f.why}` : `: ${f.why}`}`);
}

export const duetHeldSession: HeldSessionHooks = {
  intercept(req) {
    // Every method: no browser request may reach DSF's connect (it would mint a key the gateway
    // does not know) or its disconnect (it would carry the gateway's key and end its session).
    const r = connectRoute(routeOf(req.path));
    if (r === 'connect') {
      const password = paramOf(req.query, 'password');
      return password === null ? { kind: 'open' } : { kind: 'open', credentials: { password } };
    }
    if (r === 'disconnect') return { kind: 'close' };
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
