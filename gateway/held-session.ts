import type http from 'node:http';
import type { IncomingMessage, ServerResponse } from 'node:http';
import type {
  HeldCredentials,
  HeldIntercept,
  HeldSend,
  HeldSessionHooks,
  UpstreamAnswer,
} from '../src/fleet/contract';
import type { Role } from '../src/fleet/types';
import { safeAnswerHeaders } from './answer-headers';
import { HeldKey, sameCredentials, type Ensured, type HeldKeyHost } from './held-key';
import type { HeldFailure, HeldHttp, HeldRefusal, HeldRequest, HeldSocket } from './held-types';
import { BodyTooLarge, readBody, sendJson } from './http-util';
import type { MachineEntry } from './machines';
import { redactText } from './redact';
import type { ConfigService, LinksService, MachinesService, SecretsService } from './services';
import { upstreamRequest } from './upstream-request';

/**
 * Controller sessions the gateway holds (a family declares `gateway.session`, e.g. Duet DSF): the
 * session key commands the controller around every role check, so it lives here and never
 * reaches a browser. One session per machine, shared by every browser; the family's `intercept`
 * names the requests answered here, every other forwarded request gets the gateway's key in place
 * of the browser's. The rules in full: gateway/README.md, "Held controller sessions".
 */

export type { HeldHttp, HeldRefusal, HeldSocket } from './held-types';
export { upstreamRequest } from './upstream-request';

/** Bodies read here (a login's credentials, a password change). */
const MAX_INTERCEPT_BODY = 64 * 1024;

type Failure = HeldFailure;

/** What the held sessions use of the gateway (the context is one). */
export type HeldSessionHost = HeldKeyHost &
  Pick<ConfigService, 'opts'> &
  Pick<MachinesService, 'hintsOf'> &
  Pick<LinksService, 'heldSessions'> &
  Pick<SecretsService, 'patternsFor'>;

/** The gateway's session with one machine's controller: the key (held-key.ts) and the browsers' requests. */
export class HeldSession extends HeldKey {
  constructor(
    protected override readonly ctx: HeldSessionHost,
    m: MachineEntry,
    hooks: HeldSessionHooks,
  ) {
    super(ctx, m, hooks);
  }

  // ---------------------------------------------------------------- browsers

  /**
   * A browser's "open": the session's answer (typed credentials are checked with the controller
   * first; with `expiry` 'forget' every typed login is, and replaces the session's key).
   */
  private async openForBrowser(typed: HeldCredentials | undefined): Promise<Ensured> {
    const verify =
      this.configured() === undefined &&
      typed !== undefined &&
      !(this.open && this.typed !== undefined && sameCredentials(typed, this.typed));
    if (!verify) return this.ensure();
    const r = await this.openWith(typed);
    if (!r.ok) return r;
    if (this.ended) {
      if (r.key !== null) void this.closeKey(r.key, true);
      return this.closing();
    }
    if (!this.forgets) {
      this.typed = typed;
      this.ctx.learnSecret(this.m.id, typed.password);
    }
    // The session it replaces is ended on the controller, not left to expire: a standalone Duet
    // has 8 sessions, and a browser repeating its login must not use them up.
    const replaced = this.open ? this.key : null;
    this.install(r.key, r.answer);
    if (replaced !== null && replaced !== r.key) void this.closeKey(replaced);
    return { ok: true, key: r.key };
  }

  async intercepted(
    i: HeldIntercept,
    res: ServerResponse,
    r: HeldRequest & { body: Buffer; contentType: string },
  ): Promise<void> {
    this.touch();
    switch (i.kind) {
      case 'close':
        if (i.end) this.logout();
        res.writeHead(204, { 'Cache-Control': 'no-store' });
        res.end();
        return;
      case 'answer':
        this.write(res, i.answer);
        return;
      case 'exchange':
        await this.exchange(r, res);
        return;
      case 'relay':
        await this.relay(i.run, res);
        return;
      case 'open':
        break;
    }
    let typed = i.credentials;
    if (i.fromBody) {
      try {
        typed = i.fromBody(r.body.toString('utf8'), r.contentType);
      } catch {
        sendJson(res, 400, { error: 'the login request cannot be read', gateway: true });
        return;
      }
    }
    const o = await this.openForBrowser(typed);
    if (o.ok)
      this.write(
        res,
        this.answer ?? { status: 200, headers: { 'content-type': 'application/json' }, body: '{}' },
      );
    else this.refuse(res, o);
  }

  /**
   * A "relay": the family answers from requests of its own, each with the session's key (opened
   * first when there is none), never retried; a key the controller calls expired is renewed for
   * the next request. The answer goes out as the session's other answers do (redacted, content
   * type only), unless a deadline answered the browser first.
   */
  private async relay(run: (send: HeldSend) => Promise<UpstreamAnswer>, res: ServerResponse): Promise<void> {
    let refused = null as Failure | null;
    const send: HeldSend = async (method, path, query, opts = {}) => {
      // The browser's answer is out (its deadline, a page that left): nothing more is sent.
      if (res.headersSent || res.destroyed || res.writableEnded)
        throw new Error('not sent: the console stopped waiting');
      const e = await this.ensure();
      if (!e.ok) {
        refused = e;
        throw new Error(`no session with ${this.m.name}`);
      }
      const headers: Record<string, string> = {};
      const q = new URLSearchParams(query);
      this.hooks.apply({ headers, query: q }, e.key);
      this.ctx.opts.families[this.m.kind]?.gateway?.injectSecrets?.(
        { method, path, headers, query: q },
        this.m.secrets,
      );
      const qs = q.toString();
      this.inFlight++;
      this.lastUpstreamAt = Date.now();
      let a: UpstreamAnswer;
      try {
        a = await upstreamRequest(this.ctx, this.m, method, path + (qs ? `?${qs}` : ''), headers, opts);
      } catch (err) {
        refused = this.unreachable(err, `${method} ${path}`);
        throw err;
      } finally {
        this.inFlight--;
        this.touch();
      }
      if (this.hooks.isExpired(a.status, { method, path })) this.expired(e.key);
      return a;
    };
    let a: UpstreamAnswer;
    try {
      a = await run(send);
    } catch (err) {
      const f: Failure = refused ?? this.unreachable(err, 'relaying a request');
      if (!res.headersSent && !res.destroyed) this.refuse(res, f);
      return;
    }
    if (!res.headersSent && !res.destroyed) this.write(res, a);
  }

  /**
   * An "exchange": sent by the gateway with its key, never retried; a new key in the answer is
   * kept (if the session is still the one that sent it) and the answer goes out without it.
   */
  private async exchange(r: HeldRequest & { body: Buffer }, res: ServerResponse): Promise<void> {
    const e = await this.ensure();
    if (!e.ok) {
      this.refuse(res, e);
      return;
    }
    const headers = { ...r.headers };
    for (const k of Object.keys(headers))
      if (k.toLowerCase() === 'content-length' || k.toLowerCase() === 'transfer-encoding') delete headers[k];
    const query = new URLSearchParams(r.query);
    this.hooks.apply({ headers, query }, e.key);
    this.ctx.opts.families[this.m.kind]?.gateway?.injectSecrets?.(
      { method: r.method, path: r.path, headers, query },
      this.m.secrets,
    );
    const qs = query.toString();
    let a: UpstreamAnswer;
    this.inFlight++;
    this.lastUpstreamAt = Date.now();
    try {
      a = await upstreamRequest(this.ctx, this.m, r.method, r.path + (qs ? `?${qs}` : ''), headers, {
        body: r.body,
      });
    } catch (err) {
      this.refuse(res, this.unreachable(err, `${r.method} ${r.path}`));
      return;
    } finally {
      this.inFlight--;
      this.touch();
    }
    if (this.hooks.isExpired(a.status, { method: r.method, path: r.path })) this.expired(e.key);
    const x = this.hooks.exchanged?.(a, this.open ? this.answer : null) ?? { key: null, answer: a };
    if (x.key !== null) {
      if (this.open && this.key === e.key && !this.ended) this.install(x.key, x.answer);
      else {
        // The session moved on meanwhile (a logout, another login): the new key is not used.
        this.ctx.learnSecret(this.m.id, x.key);
        this.retire(x.key);
      }
    }
    this.write(res, x.answer);
  }

  /** A forwarded request: the key applied, or why there is none. */
  async use(r: HeldRequest, res: ServerResponse): Promise<HeldHttp | Failure> {
    this.touch();
    // Counted while its answer is under way: until `res` closes, or not at all when it closed
    // already (its 'close' is behind us: counted, the session would be held for ever).
    if (!res.destroyed) {
      this.inFlight++;
      res.once('close', () => {
        this.inFlight--;
        this.touch();
      });
    }
    const e = await this.ensure();
    if (!e.ok) return e;
    this.hooks.apply({ headers: r.headers, query: r.query }, e.key);
    this.lastUpstreamAt = Date.now();
    const used = e.key;
    const read = (r.method === 'GET' || r.method === 'HEAD') && !r.isCommand;
    let retried = false;
    return {
      retry: (status, resend, dropped, answerTo) => {
        if (!this.hooks.isExpired(status, { method: r.method, path: r.path })) return false;
        if (this.forgets || !read || retried) {
          // Never sent twice: the next request finds a new key (or, 'forget', none).
          this.expired(used);
          return false;
        }
        retried = true;
        if (dropped) {
          this.ctx.pending.delete(dropped.request);
          dropped.request.removeAllListeners('error');
          dropped.request.on('error', () => undefined);
          dropped.response.resume();
        }
        void this.renew(used).then((n) => {
          if (!n.ok) {
            const to = answerTo ?? res;
            if (!to.headersSent) this.refuse(to, n);
            return;
          }
          const q = new URLSearchParams(r.query);
          const before = q.toString();
          this.hooks.apply({ headers: r.headers, query: q }, n.key);
          this.lastUpstreamAt = Date.now();
          const after = q.toString();
          resend(after === before ? undefined : r.path + (after ? `?${after}` : ''));
        });
        return true;
      },
    };
  }

  /** A socket upgrade: the key for the upstream URL. */
  async socket(): Promise<HeldSocket | Failure> {
    this.touch();
    const e = await this.ensure();
    if (!e.ok) return e;
    const key = e.key;
    return {
      apply: (query, headers) => this.hooks.applyWs({ headers, query }, key),
      target: (path, rawQuery) => {
        const q = new URLSearchParams(rawQuery);
        this.hooks.applyWs({ headers: {}, query: q }, key);
        const s = q.toString();
        return path + (s ? `?${s}` : '');
      },
      track: (ws) => {
        this.sockets++;
        let gone = false;
        const end = (): void => {
          if (gone) return;
          gone = true;
          this.sockets--;
          this.touch();
        };
        ws.once('close', end);
        ws.once('error', end);
        ws.once('unexpected-response', (_req: http.ClientRequest, resp: IncomingMessage) => {
          if (this.hooks.isExpired(resp.statusCode ?? 0)) this.expired(key);
        });
      },
    };
  }

  /** An answer of the controller (connect answer, refusal), redacted like every other. */
  private write(res: ServerResponse, a: UpstreamAnswer): void {
    const patterns = this.ctx.patternsFor(this.m);
    const body = Buffer.from(patterns.length ? redactText(a.body, patterns) : a.body, 'utf8');
    const given: Record<string, string> = {};
    if (a.headers['content-type']) given['content-type'] = a.headers['content-type'];
    res.writeHead(a.status, {
      ...safeAnswerHeaders(given, { image: false }),
      'cache-control': 'no-store',
      'content-length': String(body.length),
    });
    res.end(body);
  }

  refuse(res: ServerResponse, f: Failure): void {
    if (f.answer) this.write(res, f.answer);
    else sendJson(res, f.status, { error: f.error ?? `no session with ${this.m.name}`, gateway: true });
  }
}

function hooksOf(ctx: HeldSessionHost, m: MachineEntry): HeldSessionHooks | undefined {
  return ctx.hintsOf(m).session;
}

function sessionOf(ctx: HeldSessionHost, m: MachineEntry, hooks: HeldSessionHooks): HeldSession {
  // The map holds only sessions made here (the context keeps them as handles it can end).
  const held = ctx.heldSessions.get(m.id);
  if (held instanceof HeldSession) return held;
  const s = new HeldSession(ctx, m, hooks);
  ctx.heldSessions.set(m.id, s);
  return s;
}

/**
 * For `proxy-http.ts`, after authorization and before `injectSecrets`: null when the family holds
 * no session; 'answered' when the request was answered here (connect, login, logout, disconnect,
 * an exchange, no session); else the key is in `headers`/`query` and the proxy calls `retry` with
 * the controller's status. `body`: the request body when the proxy already read it.
 */
export async function holdHttp(
  ctx: HeldSessionHost,
  m: MachineEntry,
  req: IncomingMessage,
  res: ServerResponse,
  r: HeldRequest & { body?: Buffer | null; role?: Role | undefined },
  done: (r: { status?: number; error?: string }) => void,
): Promise<'answered' | HeldHttp | null> {
  const hooks = hooksOf(ctx, m);
  if (!hooks) return null;
  const s = sessionOf(ctx, m, hooks);
  const i = hooks.intercept({
    method: r.method,
    path: r.path,
    query: r.query,
    ...(r.role ? { role: r.role } : {}),
    ...(r.body ? { body: r.body.toString('utf8') } : {}),
  });
  if (i) {
    const wantsBody = (i.kind === 'open' && i.fromBody !== undefined) || i.kind === 'exchange';
    let body = r.body ?? null;
    if (wantsBody && body === null && r.method !== 'GET' && r.method !== 'HEAD') {
      try {
        body = await readBody(req, MAX_INTERCEPT_BODY);
      } catch (e) {
        if (e instanceof BodyTooLarge) {
          sendJson(res, 413, {
            error: `request body larger than ${MAX_INTERCEPT_BODY} bytes`,
            gateway: true,
          });
          done({ status: 413 });
        } else {
          res.destroy();
          done({ error: 'the request was cut' });
        }
        return 'answered';
      }
    } else req.resume();
    const contentType = req.headers['content-type'] ?? '';
    await s.intercepted(i, res, { ...r, body: body ?? Buffer.alloc(0), contentType });
    done({ status: res.statusCode });
    return 'answered';
  }
  const u = await s.use(r, res);
  if ('retry' in u) return u;
  req.resume();
  s.refuse(res, u);
  done({ status: u.status, error: u.error });
  return 'answered';
}

/** For `proxy-ws.ts`, after authorization: null (no held session), the key, or a refusal. */
export async function holdSocket(
  ctx: HeldSessionHost,
  m: MachineEntry,
): Promise<HeldSocket | HeldRefusal | null> {
  const hooks = hooksOf(ctx, m);
  if (!hooks) return null;
  const u = await sessionOf(ctx, m, hooks).socket();
  if ('apply' in u) return u;
  return {
    status: u.status === 403 || u.status === 401 ? 403 : u.status >= 500 ? u.status : 502,
    body: { error: u.error ?? `${m.name} refused the session (HTTP ${u.status})`, gateway: true },
  };
}

/** Ends every held session (gateway close). */
export function endHeldSessions(ctx: HeldSessionHost): void {
  for (const s of ctx.heldSessions.values()) s.end();
  ctx.heldSessions.clear();
}
