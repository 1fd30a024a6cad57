import { createHash, timingSafeEqual } from 'node:crypto';
import http, { type IncomingMessage, type ServerResponse } from 'node:http';
import type { EventEmitter } from 'node:events';
import type {
  HeldCredentials,
  HeldIntercept,
  HeldSend,
  HeldSessionHooks,
  UpstreamAnswer,
  UpstreamRequest,
} from '../src/fleet/contract';
import type { Role } from '../src/fleet/types';
import { safeAnswerHeaders } from './answer-headers';
import type { GatewayContext } from './context';
import { BodyTooLarge, readBody, sendJson } from './http-util';
import { redact, type MachineEntry } from './machines';
import { redactText } from './redact';
import { connectPinned } from './tls-pin';
import { unreachableReason } from './log';

/**
 * Controller sessions the gateway holds (a family declares `gateway.session`, e.g. Duet DSF): a
 * session key lets whoever holds it command the controller directly, around every role check,
 * so the key lives here and never reaches a browser.
 *
 * - One session per machine, shared by every browser. It is opened on first use with the
 *   machine's configured credentials (`configured`, default its password), else what a user typed
 *   into the console's login form, else none. Concurrent first uses share one open.
 * - The family's `intercept` names the browser requests answered here: "open" (connect, a user
 *   login: credentials from the query or, read here, the body) gets the session's answer without
 *   the key (wrong credentials get the controller's refusal as it is); "close" (disconnect) gets
 *   204 and the shared session stays, or ends with it (`end`: a logout); "exchange" (TouchCut's
 *   password change) is sent by the gateway with its key, and a new key in the answer is kept and
 *   taken out of it; "answer" is answered as it is; "relay" is answered by the family from
 *   requests of its own with the key (RepRapFirmware's G-code replies: fetched by the gateway
 *   alone, each page given its own).
 * - Every forwarded request: whatever key the browser sent is dropped, the gateway's is added
 *   (`apply`, `applyWs`). When the controller says the key expired (`isExpired`): with `expiry`
 *   'reopen' (default) the key is renewed with the configured or typed password (kept in memory
 *   only, redacted like configured secrets), and a read (GET/HEAD that is not a command) is sent
 *   once more, a command never; with 'forget' the key is dropped, the answer goes to the browser
 *   (which asks for a login again) and nothing typed is kept.
 * - Kept alive (`keepAlive`) while a browser used the machine recently and no upstream socket
 *   holds it open; unused longer, it is ended and the next use opens a new one first.
 * - Keys and kept typed passwords are added to the machine's redaction (`ctx.learnSecret`), so
 *   that an answer, header, frame, error or audit entry that would carry them says `[redacted]`.
 *   A body read here (a login's password) is never logged nor written to the audit log.
 * - `endHeldSessions` (gateway close) ends them all.
 */

const MAX_ANSWER = 1024 * 1024;
/** Bodies read here (a login's credentials, a password change). */
const MAX_INTERCEPT_BODY = 64 * 1024;
/** Keys replaced by a renewal stay redacted for a while (late answers): this many of them. */
const RETIRED_KEPT = 4;

type Failure = { ok: false; status: number; answer?: UpstreamAnswer; error?: string };
type Ensured = { ok: true; key: string | null } | Failure;
type Opened = { ok: true; key: string | null; answer: UpstreamAnswer } | Failure;

/** Handed to the proxy for one forwarded request. */
export interface HeldHttp {
  /**
   * The controller answered `status`. True: the answer is to be dropped, the request is sent
   * again through `resend` once the key is renewed (a read whose key expired; `pathAndQuery` is
   * given when the key changed the query). `dropped`: the upstream request and its answer, to be
   * discarded. A command whose key expired renews the key for the next one and returns false.
   */
  retry(
    status: number,
    resend: (pathAndQuery?: string) => void,
    dropped?: { request: http.ClientRequest; response: IncomingMessage },
    /**
     * Where a refusal goes when no new key could be had: the browser's response by default; a
     * shared read's capture (upstream-http.ts), whose answer every waiting browser gets.
     */
    answerTo?: ServerResponse,
  ): boolean;
}

/** Handed to the WebSocket proxy for one upgrade. */
export interface HeldSocket {
  /** Drops the browser's key from the upstream query and upgrade headers, adds the gateway's. */
  apply(query: URLSearchParams, headers: Record<string, string>): void;
  /** `path?query` for a simulator's socket, with `apply` done. */
  target(path: string, rawQuery: string): string;
  /** The socket that uses the key (browser side for a simulator): the session stays while it is open. */
  track(ws: EventEmitter): void;
}

export interface HeldRefusal {
  status: number;
  body: Record<string, unknown>;
}

function sameSecret(a: string, b: string): boolean {
  const h = (s: string): Buffer => createHash('sha256').update(s, 'utf8').digest();
  return timingSafeEqual(h(a), h(b));
}

function sameCredentials(a: HeldCredentials, b: HeldCredentials): boolean {
  return sameSecret(a.password, b.password) && (a.username ?? '') === (b.username ?? '');
}

/** A forwarded request as the held session sees it (`holdHttp`). */
interface HeldRequest {
  method: string;
  path: string;
  query: URLSearchParams;
  headers: Record<string, string>;
  isCommand: boolean;
}

function flatHeaders(h: http.IncomingHttpHeaders): Record<string, string> {
  const out: Record<string, string> = {};
  for (const [k, v] of Object.entries(h))
    if (v !== undefined) out[k.toLowerCase()] = Array.isArray(v) ? v.join(', ') : v;
  return out;
}

/**
 * One request of the gateway's own to a machine: its controller (through the same agent and
 * TLS pinning as forwarded requests) or its in-process simulator. `detached`: not on the shared
 * agent nor in `pending` (requests sent while the gateway closes).
 */
export async function upstreamRequest(
  ctx: GatewayContext,
  m: MachineEntry,
  method: string,
  pathAndQuery: string,
  headers: Record<string, string> = {},
  opts: {
    detached?: boolean;
    body?: string | Buffer;
    /** The answer's body handed over as it comes (not kept, not bounded); false stops reading. */
    onData?: (chunk: Uint8Array) => boolean;
  } = {},
): Promise<UpstreamAnswer> {
  const body = method === 'GET' || method === 'HEAD' ? undefined : opts.body;
  const onData = opts.onData;
  // Simulators and serial boards (the gateway's own bridge) answer in process.
  if (m.simulated || m.serial) {
    const sim = ctx.simulatorFor(m);
    if (!sim) throw new Error(`no simulator for ${m.kind}`);
    const r = await sim.fetch(
      new Request(`http://${m.id}.sim${pathAndQuery}`, {
        method,
        headers,
        body: body === undefined ? undefined : typeof body === 'string' ? body : new Uint8Array(body),
      }),
      pathAndQuery,
    );
    const h: Record<string, string> = {};
    r.headers.forEach((v, k) => {
      h[k.toLowerCase()] = v;
    });
    if (onData && r.body) {
      const reader = r.body.getReader();
      for (;;) {
        const { done, value } = await reader.read();
        if (done) break;
        if (!onData(value)) {
          await reader.cancel();
          break;
        }
      }
      return { status: r.status, headers: h, body: '' };
    }
    return { status: r.status, headers: h, body: await r.text() };
  }
  const target = m.url;
  if (!target) throw new Error(`machine ${m.id} has no url`);
  const isHttps = target.protocol === 'https:';
  const socket = isHttps
    ? await connectPinned({
        machine: m,
        url: target,
        store: ctx.pins,
        timeoutMs: ctx.timeoutMs,
        onTrust: (r) =>
          ctx.record({
            type: 'tls-trust',
            result: 'ok',
            user: 'gateway',
            source: 'gateway',
            machine: m.id,
            detail: `trusted the certificate ${r.fingerprint} on first use`,
          }),
      })
    : null;
  return new Promise<UpstreamAnswer>((resolve, reject) => {
    const req = http.request({
      hostname: target.hostname.replace(/^\[|\]$/g, ''),
      port: target.port || (isHttps ? 443 : 80),
      method,
      path: target.pathname.replace(/\/+$/, '') + pathAndQuery,
      headers: {
        ...headers,
        host: target.host,
        ...(body !== undefined ? { 'content-length': String(Buffer.byteLength(body)) } : {}),
      },
      ...(socket ? { createConnection: () => socket } : { agent: opts.detached ? false : ctx.httpAgent }),
    });
    if (!opts.detached) ctx.pending.add(req);
    const settle = (): void => {
      ctx.pending.delete(req);
    };
    req.setTimeout(ctx.timeoutMs, () =>
      req.destroy(new Error(`the controller did not answer within ${ctx.timeoutMs} ms`)),
    );
    req.on('error', (e: Error & { code?: string }) => {
      settle();
      const reason = opts.detached || ctx.state.closed ? null : unreachableReason(e, false);
      if (reason) ctx.reachability.down(m.id, reason, redact(e.message, ctx.secretsOf.get(m.id) ?? []));
      reject(e);
    });
    req.on('response', (res) => {
      ctx.reachability.up(m.id);
      const chunks: Buffer[] = [];
      let size = 0;
      if (onData) {
        let stopped = false;
        const answer = (): UpstreamAnswer => ({
          status: res.statusCode ?? 502,
          headers: flatHeaders(res.headers),
          body: '',
        });
        res.on('data', (c: Buffer) => {
          if (stopped || onData(c)) return;
          stopped = true;
          settle();
          resolve(answer());
          req.destroy();
        });
        res.on('end', () => {
          settle();
          resolve(answer());
        });
        res.on('error', (e) => {
          settle();
          if (!stopped) reject(e);
        });
        return;
      }
      res.on('data', (c: Buffer) => {
        size += c.length;
        if (size > MAX_ANSWER) {
          req.destroy(new Error(`the controller's answer is larger than ${MAX_ANSWER} bytes`));
          return;
        }
        chunks.push(c);
      });
      res.on('end', () => {
        settle();
        resolve({
          status: res.statusCode ?? 502,
          headers: flatHeaders(res.headers),
          body: Buffer.concat(chunks).toString('utf8'),
        });
      });
      res.on('error', (e) => {
        settle();
        reject(e);
      });
    });
    req.end(body);
  });
}

/** The gateway's session with one machine's controller. */
export class HeldSession {
  private key: string | null = null;
  private open = false;
  /** The controller's connect answer without the key: what a browser's "open" gets. */
  private answer: UpstreamAnswer | null = null;
  /**
   * What a user typed into the login form (memory only; never logged, never echoed), kept to
   * reopen the session (`expiry` 'reopen' only).
   */
  private typed: HeldCredentials | undefined;
  private opening: Promise<Ensured> | null = null;
  /** Bumped whenever a session is installed or ended (an older open in flight is then discarded). */
  private generation = 0;
  private retired: string[] = [];
  private sockets = 0;
  private inFlight = 0;
  private lastUsedAt = 0;
  private lastUpstreamAt = 0;
  private timer: ReturnType<typeof setInterval> | null = null;
  private keepAliveInFlight = false;
  private ended = false;

  constructor(
    private readonly ctx: GatewayContext,
    private readonly m: MachineEntry,
    private readonly hooks: HeldSessionHooks,
  ) {}

  private readonly upstream: UpstreamRequest = (method, pathAndQuery, headers, body) =>
    upstreamRequest(this.ctx, this.m, method, pathAndQuery, headers, { body });

  /** The key is dropped when it expires, never renewed (a user login: TouchCut). */
  private get forgets(): boolean {
    return this.hooks.expiry === 'forget';
  }

  /** The machines file's credentials for the session (then a typed login is not used). */
  private configured(): HeldCredentials | undefined {
    if (this.hooks.configured) return this.hooks.configured(this.m.secrets);
    const password = this.m.secrets.password;
    return password === undefined ? undefined : { password };
  }

  // ---------------------------------------------------------------- the session

  /** The open session, opened first when there is none (one open at a time). */
  ensure(): Promise<Ensured> {
    if (this.ended) return Promise.resolve(this.closing());
    if (this.open) return Promise.resolve({ ok: true, key: this.key });
    if (!this.opening) {
      const gen = this.generation;
      const p = this.openWith(this.configured() ?? this.typed)
        .then((r): Ensured | Promise<Ensured> => {
          if (!r.ok) return r;
          if (gen !== this.generation || this.ended) {
            // A login (or the end) came first: this one is not needed.
            if (r.key !== null) void this.closeKey(r.key, this.ended);
            if (this.ended) return this.closing();
            if (this.open) return { ok: true, key: this.key };
            this.opening = null;
            return this.ensure();
          }
          this.install(r.key, r.answer);
          return { ok: true, key: r.key };
        })
        .finally(() => {
          if (this.opening === p) this.opening = null;
        });
      this.opening = p;
    }
    return this.opening;
  }

  /** The controller said `usedKey` expired: a new session (shared with whoever noticed too). */
  renew(usedKey: string | null): Promise<Ensured> {
    this.invalidate(usedKey);
    return this.ensure();
  }

  private invalidate(usedKey: string | null): void {
    if (this.open && this.key === usedKey) {
      this.open = false;
      this.generation++;
    }
  }

  /**
   * The controller said `usedKey` expired: renewed ('reopen'), or dropped ('forget': the next use
   * finds the session without a key, as the configured credentials open it).
   */
  private expired(usedKey: string | null): void {
    if (!this.forgets) {
      void this.renew(usedKey);
      return;
    }
    if (usedKey === null || !this.open || this.key !== usedKey) return;
    this.open = false;
    this.generation++;
    this.key = null;
    this.answer = null;
    this.retire(usedKey);
  }

  /** A logout for every viewer: the key is dropped (and closed), typed credentials forgotten. */
  private logout(): void {
    this.typed = undefined;
    this.stopTimer();
    const key = this.open ? this.key : null;
    this.open = false;
    this.generation++;
    this.key = null;
    this.answer = null;
    if (key !== null) {
      this.retire(key);
      void this.closeKey(key);
    }
  }

  private closing(): Failure {
    return { ok: false, status: 503, error: 'the gateway is shutting down' };
  }

  private async openWith(credentials: HeldCredentials | undefined): Promise<Opened> {
    try {
      const r = await this.hooks.open(this.upstream, credentials);
      return r.ok ? r : { ok: false, status: r.answer.status, answer: r.answer };
    } catch (e) {
      return this.unreachable(e, 'opening the controller session');
    }
  }

  /** A request of the gateway's own failed: logged (redacted), and the failure for the browser. */
  private unreachable(e: unknown, doing: string): Failure {
    const err = e instanceof Error ? e : new Error(String(e));
    const forms = this.ctx.secretsOf.get(this.m.id) ?? [];
    const reason = this.ctx.state.closed ? null : unreachableReason(err, false);
    if (reason) this.ctx.reachability.down(this.m.id, reason, redact(err.message, forms));
    else
      this.ctx.log.error(`${this.m.id}: ${doing}: ${redact(err.message, forms)}`, {
        machine: this.m.id,
      });
    const timedOut = /did not answer within/.test(err.message);
    return {
      ok: false,
      status: timedOut ? 504 : 502,
      error: timedOut ? `${this.m.name} did not answer in time` : `cannot reach ${this.m.name}`,
    };
  }

  private install(key: string | null, answer: UpstreamAnswer): void {
    if (this.key !== null && this.key !== key) this.retire(this.key);
    if (key !== null) this.ctx.learnSecret(this.m.id, key);
    this.key = key;
    this.answer = answer;
    this.open = true;
    this.generation++;
    this.lastUpstreamAt = Date.now();
    this.startTimer();
  }

  /** A key no longer used stays redacted a while, then is forgotten. */
  private retire(key: string): void {
    this.retired.push(key);
    while (this.retired.length > RETIRED_KEPT) {
      const old = this.retired.shift();
      if (old !== undefined && old !== this.key) this.ctx.learnSecret(this.m.id, old, false);
    }
  }

  private async closeKey(key: string, detached = false): Promise<void> {
    if (!this.hooks.close) return;
    const upstream: UpstreamRequest = (method, pathAndQuery, headers, body) =>
      upstreamRequest(this.ctx, this.m, method, pathAndQuery, headers, { detached, body });
    try {
      await this.hooks.close(upstream, key);
    } catch {
      // best effort: the controller forgets it on its own
    }
  }

  /** Unused: end the session; the next use opens a new one. */
  private release(): void {
    this.stopTimer();
    if (!this.open) return;
    const key = this.key;
    this.open = false;
    this.generation++;
    this.key = null;
    if (key !== null) {
      this.retire(key);
      void this.closeKey(key);
    }
  }

  /** The gateway closes: end the session (best effort: nothing waits for the controller). */
  end(): void {
    this.ended = true;
    this.stopTimer();
    const key = this.open ? this.key : null;
    this.open = false;
    this.generation++;
    if (key !== null) void this.closeKey(key, true);
  }

  // ---------------------------------------------------------------- keep-alive

  private touch(): void {
    this.lastUsedAt = Date.now();
    this.startTimer();
  }

  private startTimer(): void {
    const ka = this.hooks.keepAlive;
    if (!ka || this.timer || this.ended || !this.open) return;
    this.timer = setInterval(() => this.tick(), ka.everyMs);
    this.timer.unref();
  }

  private stopTimer(): void {
    if (this.timer) clearInterval(this.timer);
    this.timer = null;
  }

  private tick(): void {
    const ka = this.hooks.keepAlive;
    if (!ka || this.ended || !this.open) {
      this.stopTimer();
      return;
    }
    // An open socket keeps the session on the controller's side.
    if (this.sockets > 0) return;
    const now = Date.now();
    if (this.inFlight === 0 && now - this.lastUsedAt > ka.whileUsedWithinMs) {
      this.release();
      return;
    }
    if (this.key === null || this.keepAliveInFlight || now - this.lastUpstreamAt < ka.everyMs / 2) return;
    const key = this.key;
    const headers: Record<string, string> = {};
    this.hooks.apply({ headers, query: new URLSearchParams() }, key);
    this.keepAliveInFlight = true;
    this.lastUpstreamAt = now;
    this.upstream('GET', ka.path, headers)
      .then(
        (r) => {
          if (!this.hooks.isExpired(r.status)) return;
          if (this.forgets) this.expired(key);
          else this.invalidate(key);
        },
        () => undefined,
      )
      .finally(() => {
        this.keepAliveInFlight = false;
      });
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

function hooksOf(ctx: GatewayContext, m: MachineEntry): HeldSessionHooks | undefined {
  return ctx.hintsOf(m).session;
}

function sessionOf(ctx: GatewayContext, m: MachineEntry, hooks: HeldSessionHooks): HeldSession {
  let s = ctx.heldSessions.get(m.id);
  if (!s) {
    s = new HeldSession(ctx, m, hooks);
    ctx.heldSessions.set(m.id, s);
  }
  return s;
}

/**
 * For `proxy-http.ts`, after authorization and before `injectSecrets`: null when the family holds
 * no session; 'answered' when the request was answered here (connect, login, logout, disconnect,
 * an exchange, no session); else the key is in `headers`/`query` and the proxy calls `retry` with
 * the controller's status. `body`: the request body when the proxy already read it.
 */
export async function holdHttp(
  ctx: GatewayContext,
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
  ctx: GatewayContext,
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
export function endHeldSessions(ctx: GatewayContext): void {
  for (const s of ctx.heldSessions.values()) s.end();
  ctx.heldSessions.clear();
}
