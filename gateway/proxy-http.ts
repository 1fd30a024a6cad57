import http, { IncomingMessage, type ServerResponse } from 'node:http';
import { Socket } from 'node:net';
import https from 'node:https';
import type { TLSSocket } from 'node:tls';
import { pipeline, type Transform } from 'node:stream';
import { SimDropped, splitPath } from '../src/fleet/sim';
import { safeAnswerHeaders } from './answer-headers';
import { createRedactor, decoderFor, redactBytes } from './redact';
import { CertificateChanged, connectPinned, PinFileError } from './tls-pin';
import {
  BodyTooLarge,
  clientAddress,
  commandDeadlineMs,
  forwardRequestHeaders,
  forwardResponseHeaders,
  markStreamedBody,
  readBody,
  secondsWords,
  sendJson,
} from './http-util';
import { redact, type MachineEntry } from './machines';
import { holdHttp, type HeldHttp } from './held-session';
import { auditTarget, splitTarget, type SplitTarget } from './paths';
import type { GatewayContext, Verdict } from './context';
import { crossSiteProblem } from './csrf';
import type { AccessDecision } from '../src/fleet/access';
import type { Role } from '../src/fleet/types';
import { unreachableReason } from './log';
import { AnswerTooLarge, captureAnswer } from './upstream-http';

const MAX_CLASSIFY_BODY = 1024 * 1024;
const MAX_SIM_BODY = 64 * 1024 * 1024;
/** The watch reads status answers: a few kB; a model (Duet) some tens. */
const WATCH_READ_MAX = 2 * 1024 * 1024;
export const READ_METHODS = new Set(['GET', 'HEAD', 'OPTIONS']);

function hasBody(req: IncomingMessage): boolean {
  const cl = req.headers['content-length'];
  return (cl !== undefined && cl.trim() !== '0') || req.headers['transfer-encoding'] !== undefined;
}

/** What a request's outcome says for the audit log (commands only). */
type Done = (r: { status?: number; error?: string }) => void;

/**
 * One command on its way to a controller (issue 15): its deadline, and whether it may still be
 * sent. A command is never delivered after the operator was told it was not confirmed:
 *
 * - At the deadline (`X-Shopdeck-Deadline` from the browser, capped; the gateway's timeout when
 *   absent; none for a command whose body streams through, an upload, which keeps the idle
 *   timeout) everything under way for it is aborted — a connection still being made or a TLS
 *   handshake still under way is dropped before a byte of the request is written — and the
 *   browser is answered 504 "not confirmed" (or its answer is cut, when the controller's had
 *   begun).
 * - A browser that leaves (its own timeout, a closed page) stops it the same way.
 * - `sent`: the connection was made, so the request may have reached the controller. Once bytes
 *   are written nothing can call them back: "it may or may not have reached the machine".
 */
class CommandWatch {
  /** Why the command may not be sent any more (null: it may still go). */
  stopped: 'deadline' | 'browser' | null = null;
  sent = false;
  private readonly aborts = new Set<() => void>();
  private timer: ReturnType<typeof setTimeout> | null = null;
  private readonly endsAt: number | null;

  constructor(
    /** The deadline in ms from the request's arrival; null: none. */
    readonly ms: number | null,
    arrivedAt: number,
    private readonly expired: (w: CommandWatch) => void,
  ) {
    this.endsAt = ms === null ? null : arrivedAt + ms;
    if (this.endsAt !== null)
      this.timer = setTimeout(() => this.stop('deadline'), Math.max(0, this.endsAt - Date.now()));
  }

  /** Ms left until the deadline (Infinity: none). */
  remaining(): number {
    return this.endsAt === null ? Number.POSITIVE_INFINITY : Math.max(0, this.endsAt - Date.now());
  }

  /** Runs `abort` when the command stops (at once when it has). Returns: forget it. */
  onAbort(abort: () => void): () => void {
    if (this.stopped) {
      abort();
      return () => undefined;
    }
    this.aborts.add(abort);
    return () => this.aborts.delete(abort);
  }

  stop(why: 'deadline' | 'browser'): void {
    if (this.stopped) return;
    this.stopped = why;
    this.settle();
    if (why === 'deadline') this.expired(this);
    const aborts = [...this.aborts];
    this.aborts.clear();
    for (const a of aborts) a();
  }

  /** The answer was given (or the browser is gone): no deadline any more. */
  settle(): void {
    if (this.timer) clearTimeout(this.timer);
    this.timer = null;
  }
}

/**
 * A redirect to the controller itself (absolute URL or absolute path) becomes the same place
 * under `/machines/<id>`, so the browser stays on the console's origin. Relative redirects
 * already resolve under `/machines/<id>`. A redirect to another origin is null: refused (it would
 * send the browser, or its request, to a site the machines file does not name).
 */
export function rewriteLocation(
  location: string,
  target: URL,
  id: string,
  /** The controller path the redirect answers (relative redirects resolve against it). */
  requestPath = '/',
): string | null {
  const basePath = target.pathname.replace(/\/+$/, '');
  let u: URL;
  try {
    // Relative redirects too: `../../other-machine/…` must not leave this machine's prefix.
    u = new URL(location, target.origin + basePath + requestPath);
  } catch {
    return null;
  }
  if (u.origin !== target.origin) return null;
  let p = u.pathname;
  if (basePath && (p === basePath || p.startsWith(`${basePath}/`))) p = p.slice(basePath.length) || '/';
  return `/machines/${encodeURIComponent(id)}${p}${u.search}${u.hash}`;
}

export function createHttpProxy(ctx: GatewayContext) {
  const {
    opts,
    timeoutMs,
    secretsOf,
    pending,
    httpAgent,
    record,
    patternsFor,
    pins,
    scrub,
    who,
    classify,
    authorize,
    simulatorFor,
    log,
    reachability,
  } = ctx;

  /**
   * A failed upstream request: a controller that cannot be reached goes offline (one line per
   * machine, reachability in log.ts); any other failure is logged as it happens.
   */
  function upstreamFailed(m: MachineEntry, e: Error & { code?: string }, timedOut: boolean): void {
    const detail = redact(e.message, secretsOf.get(m.id) ?? []);
    const reason = unreachableReason(e, timedOut);
    if (reason) reachability.down(m.id, reason, detail);
    else log.error(`${m.id}: ${detail}`, { machine: m.id });
  }

  // ---------------------------------------------------------------- /machines (HTTP)

  /** Answers a refused request and writes it to the audit log. */
  function refuse(
    req: IncomingMessage,
    res: ServerResponse,
    m: MachineEntry,
    method: string,
    t: SplitTarget,
    decision: AccessDecision,
    v: Extract<Verdict, { ok: false }>,
  ): void {
    const p = who(req, false).principal;
    record({
      type: 'refused',
      result: 'refused',
      machine: m.id,
      method,
      path: scrub(auditTarget(t)),
      label: decision.label,
      address: clientAddress(req),
      source: 'gateway',
      user: p?.name ?? 'nobody',
      onBehalfOf: p?.onBehalfOf,
      role: decision.role,
      error: String(v.body.error),
    });
    req.resume();
    sendJson(res, v.status, v.body);
  }

  async function proxy(
    req: IncomingMessage,
    res: ServerResponse,
    m: MachineEntry,
    rest: string,
  ): Promise<void> {
    const arrivedAt = Date.now();
    const method = (req.method ?? 'GET').toUpperCase();
    const address = clientAddress(req);
    const t = splitTarget(rest);
    if ('error' in t) {
      sendJson(res, 400, { error: t.error });
      return;
    }
    const fam = opts.families[m.kind];
    let body: Buffer | null = null;
    const needsBody = fam?.accessNeedsBody?.(method, t.path) ?? false;
    if (needsBody) {
      // Authorize before reading a body: whatever the body says, the request needs at least
      // this role (a body-classified request is a command: operator unless the family says).
      const least: AccessDecision = {
        role: needsBody === true ? 'operator' : needsBody,
        command: true,
        label: `${method} ${t.path}`,
      };
      const pre = authorize(who(req, false), m, least);
      if (!pre.ok) {
        refuse(req, res, m, method, t, least, pre);
        return;
      }
      const limit = fam?.accessBodyLimit?.(method, t.path) ?? MAX_CLASSIFY_BODY;
      try {
        body = await readBody(req, limit);
      } catch (e) {
        if (e instanceof BodyTooLarge) {
          sendJson(res, 413, { error: `request body larger than ${limit} bytes` });
          return;
        }
        throw e;
      }
    }
    const contentType = body ? req.headers['content-type'] : undefined;
    const decision = classify(m, {
      method,
      path: t.path,
      query: t.query,
      body: body?.toString('utf8'),
      contentType,
    });
    const isCommand = !READ_METHODS.has(method) || decision.command;
    if (isCommand) {
      // A GET the family marks as a command (`/cnc/data?action=stop`) needs the same proof as a
      // POST that the console sent it (non-GET requests were checked in gateway.ts already).
      const crossSite = crossSiteProblem(req, 'command');
      if (crossSite) {
        refuse(req, res, m, method, t, decision, {
          ok: false,
          status: 403,
          body: { error: `refused: ${crossSite}`, crossSite: true },
        });
        return;
      }
    }
    const w = who(req, isCommand);
    const auditPath = scrub(auditTarget(t));
    // The command is what the gateway classified (`decision.id`); the page's own name for it
    // (`X-Shopdeck-Command`) is kept as a label only: a forged one must not name another command.
    const clientCommand =
      typeof req.headers['x-shopdeck-command'] === 'string'
        ? scrub(req.headers['x-shopdeck-command'].slice(0, 100))
        : undefined;
    const base = {
      machine: m.id,
      method,
      path: auditPath,
      commandId: decision.id,
      clientCommand,
      label: decision.label,
      address,
      source: 'gateway' as const,
    };
    const v = authorize(w, m, decision);
    if (!v.ok) {
      if (v.status === 403 || isCommand) {
        record({
          ...base,
          type: 'refused',
          result: 'refused',
          user: w.principal?.name ?? 'nobody',
          onBehalfOf: w.principal?.onBehalfOf,
          role: decision.role,
          error: String(v.body.error),
        });
      }
      req.resume();
      sendJson(res, v.status, v.body);
      return;
    }
    // A command's entry is committed before it is forwarded (a crash after this point leaves it
    // "pending", never missing); one that cannot be audited is not sent.
    const audit = isCommand
      ? ctx.beginCommand({ ...base, user: v.principal.name, onBehalfOf: v.principal.onBehalfOf })
      : null;
    if (isCommand && !audit) {
      req.resume();
      gatewayError(
        res,
        503,
        `${decision.label}: not sent, the audit log cannot be written (see the server log)`,
      );
      return;
    }
    /** A command's outcome, audited once (the first word on it counts: a deadline, a cut answer…). */
    const done: Done = (r) => audit?.done(r);

    let watch: CommandWatch | null = null;
    if (isCommand) {
      // A command whose body streams through (an upload) has no default deadline: its transfer
      // may take long; the idle timeout applies as for reads. Any other command has one.
      const streamed = body === null && hasBody(req);
      const ms = commandDeadlineMs(req.headers['x-shopdeck-deadline'], streamed ? null : timeoutMs);
      const cw = new CommandWatch(ms, arrivedAt, () => {
        const secs = secondsWords(ms ?? 0);
        done({
          status: 504,
          error: `not confirmed within ${secs}: ${
            cw.sent
              ? 'the request was sent; the controller did not answer in time'
              : 'the request was not sent (the controller could not be reached in time)'
          }`,
        });
        if (!res.headersSent && !res.destroyed)
          gatewayError(
            res,
            504,
            `${m.name} did not confirm ${decision.label} within ${secs}: it may or may not have reached the machine`,
            true,
          );
        else res.destroy();
      });
      res.once('close', () => {
        if (res.writableFinished) {
          cw.settle();
          return;
        }
        // The browser stopped waiting (its own deadline, a closed page): not sent after that.
        done({
          error: cw.sent
            ? 'not confirmed: the console stopped waiting (the request was sent)'
            : 'not sent: the console stopped waiting before the controller could be reached',
        });
        cw.stop('browser');
      });
      watch = cw;
    }

    await sendUpstream(
      req,
      res,
      m,
      method,
      t,
      forwardRequestHeaders(req.headers),
      body,
      isCommand,
      done,
      watch,
      v.principal.role,
    );
  }

  /**
   * An authorized request on its way to the controller: the held session's key, the family's
   * secrets, then one upstream per machine (upstream-http.ts). Also the way of the gateway's own
   * reads (the watch, `watchRead`), which have no browser behind them.
   */
  async function sendUpstream(
    req: IncomingMessage,
    res: ServerResponse,
    m: MachineEntry,
    method: string,
    t: SplitTarget,
    headers: Record<string, string>,
    body: Buffer | null,
    isCommand: boolean,
    done: Done,
    watch: CommandWatch | null = null,
    /** The browser's role (a family's held session may answer by it: a Duet job start). */
    role?: Role,
  ): Promise<void> {
    const fam = opts.families[m.kind];
    if (patternsFor(m).length) {
      // A range of an answer could cut a secret into pieces too short to recognise.
      delete headers.range;
      delete headers['if-range'];
    }
    const query = new URLSearchParams(t.query);
    const before = query.toString();
    // Held controller session (held-session.ts): connect/disconnect are answered there, the
    // browser's key is dropped and the gateway's added; `held` re-sends an expired read once.
    const held = await holdHttp(
      ctx,
      m,
      req,
      res,
      { method, path: t.path, query, headers, isCommand, body, role },
      done,
    );
    if (held === 'answered') return;
    // The deadline passed (or the browser left) while the held session was being opened: not sent.
    if (watch?.stopped) return;
    fam?.gateway?.injectSecrets?.({ method, path: t.path, headers, query }, m.secrets);
    const qs = query.toString() === before ? t.rawQuery : query.toString();
    const pathAndQuery = t.path + (qs ? `?${qs}` : '');

    const url = m.url;
    // A serial board (m.serial) is answered by the gateway's bridge, like a simulator.
    if (!m.simulated && !url && !m.serial) {
      sendJson(res, 502, { error: `machine ${m.id} has no url` });
      return;
    }
    // One upstream per machine (upstream-http.ts): identical reads shared, reads limited, commands
    // at once. `sink` is the browser's response, or a capture whose answer several browsers get.
    await ctx.upstream.send(
      { machine: m, req, res, method, path: t.path, query: t.query, pathAndQuery, headers, isCommand, held },
      (sink, agent, h) =>
        m.simulated || !url
          ? answerFromSimulator(req, sink, m, method, pathAndQuery, headers, body, done, h, watch)
          : forward(req, sink, m, url, method, t.path, pathAndQuery, headers, body, done, h, agent, watch),
    );
  }

  async function answerFromSimulator(
    req: IncomingMessage,
    res: ServerResponse,
    m: MachineEntry,
    method: string,
    pathAndQuery: string,
    headers: Record<string, string>,
    buffered: Buffer | null,
    done: Done,
    held: HeldHttp | null = null,
    watch: CommandWatch | null = null,
  ): Promise<void> {
    if (watch?.stopped) {
      req.resume();
      return;
    }
    const sim = simulatorFor(m);
    if (!sim) {
      req.resume();
      sendJson(res, 503, { error: `no simulator for ${m.kind}: the family is not registered` });
      done({ status: 503 });
      return;
    }
    let body: Buffer | null = buffered;
    if (!body && method !== 'GET' && method !== 'HEAD') {
      markStreamedBody(req);
      body = await readBody(req, MAX_SIM_BODY);
    }
    if (watch?.stopped) return;
    // A simulator's request is aborted with the command (a simulator that waits may look at it).
    const abort = new AbortController();
    const unwatch = watch?.onAbort(() => abort.abort());
    const request = new Request(`http://${m.id}.sim${pathAndQuery}`, {
      method,
      headers,
      body: body && method !== 'GET' && method !== 'HEAD' ? new Uint8Array(body) : undefined,
      signal: abort.signal,
    });
    if (watch) watch.sent = true;
    let answer: Response;
    try {
      answer = await sim.fetch(request, pathAndQuery);
    } catch (e) {
      unwatch?.();
      // Answered already (the deadline passed, the browser left).
      if (watch?.stopped || res.headersSent || res.destroyed) return;
      done({ error: e instanceof SimDropped ? 'connection dropped (simulated)' : String(e) });
      if (e instanceof SimDropped) res.destroy();
      else sendJson(res, 502, { error: `simulator failed: ${e instanceof Error ? e.message : String(e)}` });
      return;
    }
    unwatch?.();
    if (watch?.stopped || res.headersSent || res.destroyed) return;
    // Held session (held-session.ts): a read whose key expired is sent once more with a new key.
    const again = (pq?: string): void =>
      void answerFromSimulator(req, res, m, method, pq ?? pathAndQuery, headers, buffered, done);
    if (held?.retry(answer.status, again)) return;
    const given: Record<string, string> = {};
    answer.headers.forEach((value, key) => {
      const k = key.toLowerCase();
      if (k !== 'content-length' && k !== 'content-encoding') given[k] = value;
    });
    // Simulated answers get the same treatment as a controller's (answer-headers.ts, redact.ts).
    const fam = opts.families[m.kind];
    const out = safeAnswerHeaders(given, {
      image: fam?.gateway?.imageAnswer?.(splitPath(pathAndQuery).pathname) ?? false,
    });
    // A serial board's bridge is the gateway's own code (it builds every answer; the board's
    // bytes never make a header): its "board not connected" answers are the gateway's failures.
    if (m.serial && answer.status >= 500 && given['x-shopdeck-gateway'] === 'error')
      out['X-Shopdeck-Gateway'] = 'error';
    const patterns = patternsFor(m);
    const raw = Buffer.from(await answer.arrayBuffer());
    const buf = patterns.length ? redactBytes(raw, patterns) : raw;
    res.writeHead(answer.status, { ...out, 'Content-Length': String(buf.length) });
    res.end(method === 'HEAD' ? undefined : buf);
    done({ status: answer.status });
  }

  /** Words for a failed upstream request, without the controller's address (viewers read them). */
  function upstreamWords(m: MachineEntry, e: Error & { code?: string }, timedOut: boolean): string {
    if (timedOut)
      return `${m.name} did not answer within ${timeoutMs < 1000 ? `${timeoutMs} ms` : `${Math.round(timeoutMs / 1000)} s`}`;
    if (e instanceof CertificateChanged) return e.message;
    if (e instanceof PinFileError) return e.message;
    switch (e.code) {
      case 'ECONNREFUSED':
        return `${m.name} refused the connection (is the controller on and its web server running?)`;
      case 'EHOSTUNREACH':
      case 'ENETUNREACH':
      case 'ETIMEDOUT':
        return `${m.name} cannot be reached on the network`;
      case 'ENOTFOUND':
      case 'EAI_AGAIN':
        return `the address of ${m.name} cannot be resolved`;
      case 'ECONNRESET':
      case 'EPIPE':
        return `${m.name} closed the connection`;
      default:
        return `cannot reach ${m.name}`;
    }
  }

  /**
   * The gateway's own failure (not the controller's answer): marked so the page can tell
   * (`X-Shopdeck-Gateway: error`, `gateway: true`). `notConfirmed`: a command that may or may not
   * have reached the controller (it was written, or may have been); without it, a command's
   * failure means it was not sent.
   */
  function gatewayError(res: ServerResponse, status: number, error: string, notConfirmed = false): void {
    sendJson(res, status, { error, gateway: true, ...(notConfirmed ? { notConfirmed: true } : {}) });
  }

  async function forward(
    req: IncomingMessage,
    res: ServerResponse,
    m: MachineEntry,
    target: URL,
    method: string,
    path: string,
    pathAndQuery: string,
    headers: Record<string, string>,
    body: Buffer | null,
    done: Done,
    held: HeldHttp | null = null,
    /** For `http:` controllers (upstream-http.ts: the machine's reads may keep connections alive). */
    agent: http.Agent = httpAgent,
    /** A command's deadline and abort (null: a read). */
    watch: CommandWatch | null = null,
  ): Promise<void> {
    // Stopped before it left (the deadline passed, the browser left): never sent.
    if (watch?.stopped || res.destroyed) {
      req.resume();
      return;
    }
    const isHttps = target.protocol === 'https:';
    const basePath = target.pathname.replace(/\/+$/, '');
    const forms = secretsOf.get(m.id) ?? [];
    const patterns = patternsFor(m);
    const fam = opts.families[m.kind];
    if (body) headers['content-length'] = String(body.length);
    else if (req.headers['content-length']) headers['content-length'] = req.headers['content-length'];
    else if (req.headers['transfer-encoding']) headers['transfer-encoding'] = 'chunked';
    let tlsSocket: TLSSocket | null = null;
    if (isHttps) {
      // The controller's certificate is checked (configured fingerprint or trust on first use)
      // before one byte of the request, and so before any secret, is written (tls-pin.ts).
      try {
        tlsSocket = await connectPinned({
          machine: m,
          url: target,
          store: pins,
          // A command's deadline ends the handshake too (its own 504 comes first: a little later).
          timeoutMs: Math.min(timeoutMs, (watch?.remaining() ?? Number.POSITIVE_INFINITY) + 100),
          onTrust: (r) =>
            record({
              type: 'tls-trust',
              result: 'ok',
              user: 'gateway',
              source: 'gateway',
              machine: m.id,
              detail: `trusted the certificate ${r.fingerprint} on first use`,
            }),
        });
      } catch (e) {
        // Answered already: the deadline passed, or the browser left, during the handshake.
        if (watch?.stopped) return;
        const err = e instanceof Error ? e : new Error(String(e));
        const words = upstreamWords(m, err, false);
        upstreamFailed(m, err, false);
        req.resume();
        done({ error: words });
        gatewayError(res, 502, words);
        return;
      }
      // The browser left, or the deadline passed, while the certificate was checked: not a byte
      // of the request is written.
      if (res.destroyed || watch?.stopped) {
        tlsSocket.destroy();
        return;
      }
    }
    const socket = tlsSocket;
    let upstream: http.ClientRequest;
    try {
      upstream = (isHttps ? https : http).request({
        protocol: target.protocol,
        hostname: target.hostname.replace(/^\[|\]$/g, ''),
        port: target.port || (isHttps ? 443 : 80),
        method,
        path: basePath + pathAndQuery,
        headers: { ...headers, host: target.host },
        ...(socket ? { createConnection: () => socket } : { agent }),
      });
    } catch (e) {
      // Node refused to build it (a path or header it cannot write): not a byte was sent. Answered
      // here like any failure, so the read's slot, the pinned socket and a command's audit line
      // are not left to a throw that nothing would end.
      socket?.destroy();
      const words = `${m.name}: the gateway could not send this request (${redact(
        e instanceof Error ? e.message : String(e),
        forms,
      )})`;
      req.resume();
      done({ error: `not sent: ${words}` });
      gatewayError(res, 502, words);
      return;
    }
    pending.add(upstream);
    // However it ends (error, answer, abandoned): not kept among the requests under way.
    upstream.once('close', () => pending.delete(upstream));
    // A command: aborted at its deadline or when the browser leaves. Destroyed while its
    // connection is still being made, the request is never written.
    const unwatch = watch?.onAbort(() => upstream.destroy()) ?? (() => undefined);
    if (watch) {
      if (socket) watch.sent = true;
      else
        upstream.once('socket', (s) => {
          if (!s.connecting) watch.sent = true;
          else s.once('connect', () => (watch.sent = true));
        });
    }
    let timedOut = false;
    let finished = false;
    /** The browser went away and the gateway ended the request: not the controller's doing. */
    let abandoned = false;
    const finish = (r: { status?: number; error?: string }): void => {
      if (finished) return;
      finished = true;
      pending.delete(upstream);
      unwatch();
      res.off('close', onBrowserGone);
      done(r);
    };
    // An idle timeout (it covers the answer's body too), except for a command with a deadline:
    // its deadline covers everything from its arrival to the answer's last byte.
    if (!watch || watch.ms === null)
      upstream.setTimeout(timeoutMs, () => {
        timedOut = true;
        upstream.destroy(new Error(`the controller did not answer within ${timeoutMs} ms`));
      });
    /** A command that may have reached the controller: its failure is "not confirmed". */
    const unconfirmed = (): boolean => watch !== null && watch.sent;
    upstream.on('error', (e: Error & { code?: string }) => {
      // Answered already (whole, refused, or sent again with a new key): nothing more to say.
      if (finished) return;
      // Stopped by its watch (deadline, browser gone): answered and audited there.
      if (watch?.stopped) {
        finish({ error: 'aborted' });
        return;
      }
      const words = upstreamWords(m, e, timedOut);
      if (!abandoned && !ctx.state.closed) upstreamFailed(m, e, timedOut);
      finish({ error: unconfirmed() ? `not confirmed: ${words}` : words });
      if (!res.headersSent) gatewayError(res, timedOut ? 504 : 502, words, unconfirmed());
      else res.destroy();
    });
    const onBrowserGone = (): void => {
      if (res.writableFinished) return;
      abandoned = true;
      upstream.destroy();
    };
    res.on('close', onBrowserGone);
    upstream.on('response', (up) => {
      reachability.up(m.id);
      const status = up.statusCode ?? 502;
      // Held session (held-session.ts): a read whose key expired is sent once more with a new key.
      const again = (pq?: string): void =>
        void forward(
          req,
          res,
          m,
          target,
          method,
          path,
          pq ?? pathAndQuery,
          headers,
          body,
          done,
          null,
          agent,
          watch,
        );
      if (held?.retry(status, again, { request: upstream, response: up })) {
        // Sent again with a new key (a forward of its own): this one lets go of the response.
        finished = true;
        pending.delete(upstream);
        unwatch();
        res.off('close', onBrowserGone);
        return;
      }
      const given = forwardResponseHeaders(up.headers);
      for (const [k, v] of Object.entries(given)) {
        given[k] = Array.isArray(v) ? v.map((x) => redact(x, forms)) : redact(v, forms);
      }
      const location = given.location;
      if (typeof location === 'string') {
        const rewritten = rewriteLocation(location, target, m.id, pathAndQuery);
        if (rewritten === null) {
          // A redirect away from the controller would take the browser (or its credentials)
          // to another site: refused.
          up.resume();
          upstream.destroy();
          finish({ status: 502, error: 'the controller redirected to another site' });
          gatewayError(
            res,
            502,
            `${m.name} answered with a redirect to another site: refused`,
            watch !== null,
          );
          return;
        }
        given.location = rewritten;
      }
      const out = safeAnswerHeaders(given, { image: fam?.gateway?.imageAnswer?.(path) ?? false });
      const decoder = decoderFor(up.headers['content-encoding']);
      if (decoder === 'refuse') {
        up.resume();
        upstream.destroy();
        finish({ status: 502, error: 'an answer encoded in a way the gateway cannot check' });
        gatewayError(
          res,
          502,
          `${m.name} sent an answer the gateway cannot check (Content-Encoding)`,
          watch !== null,
        );
        return;
      }
      // Every byte passes the redactor (any type, any size, decoded first); its length may change.
      const stages: Transform[] = [];
      if (decoder) stages.push(decoder);
      if (patterns.length) stages.push(createRedactor(patterns));
      if (stages.length) delete out['content-length'];
      res.writeHead(status, out);
      if (method === 'HEAD') {
        up.resume();
        res.end();
        finish({ status });
        return;
      }
      // A cut answer (the controller's connection breaks midway) ends the browser's response
      // at once, as an error, never as a complete answer and never left open.
      pipeline([up, ...stages, res], (err) => {
        if (err) {
          res.destroy();
          const cut = `the answer was cut: ${redact(err.message, forms)}`;
          finish({ status, error: watch ? `not confirmed: ${cut}` : cut });
        } else finish({ status });
      });
    });
    if (body) upstream.end(body);
    else if (method === 'GET' || method === 'HEAD') {
      req.resume();
      upstream.end();
    } else {
      markStreamedBody(req);
      req.pipe(upstream);
    }
  }

  /**
   * The gateway's own read of a machine (its watch, watch.ts): no browser behind it, so no user
   * and no role check, hence only what the family classifies as a read. It takes the browsers'
   * way (held session, secrets, sharing: within a window it costs the controller nothing).
   */
  async function watchRead(
    m: MachineEntry,
    pathAndQuery: string,
  ): Promise<{ status: number; body: string; gateway: boolean }> {
    const t = splitTarget(pathAndQuery);
    if ('error' in t) throw new Error(t.error);
    const decision = classify(m, { method: 'GET', path: t.path, query: t.query });
    if (decision.command) throw new Error(`${t.path} is a command: the watch only reads`);
    const req = new IncomingMessage(new Socket());
    req.method = 'GET';
    req.url = pathAndQuery;
    req.push(null);
    const { res, answer } = captureAnswer(WATCH_READ_MAX);
    try {
      await sendUpstream(req, res, m, 'GET', t, {}, null, false, () => undefined);
    } catch (e) {
      // Closed, so whatever counts it (the held session's reads under way) lets go of it.
      res.destroy();
      answer.catch(() => undefined);
      throw e;
    }
    const a = await answer;
    // `X-Shopdeck-Gateway` is the gateway's own (a controller's is never passed on): unreachable.
    const gateway = a.headers['x-shopdeck-gateway'] !== undefined;
    return { status: a.status, body: a.body.toString('utf8'), gateway };
  }

  /**
   * A read a page sends over its read socket (read-socket.ts) instead of an HTTP GET: the same
   * checks as that GET (who the socket's user is now, the family's classification, the role), the
   * same way upstream (held session, secrets, one upstream per machine, shared reads), and the
   * answer captured whole, at most `cap` bytes. Never a command: a request the family classifies
   * as one is not sent (`fallback`), the page sends it over HTTP, where commands are proven and
   * audited.
   */
  async function socketRead(
    from: IncomingMessage,
    m: MachineEntry,
    rest: string,
    browserHeaders: Record<string, string>,
    cap: number,
    /** The page gave up or its socket closed: the read is abandoned (its upstream slot freed). */
    signal?: AbortSignal,
    /** Each chunk of the answer as it is gathered: false refuses it (the answer is too large). */
    take?: (bytes: number) => boolean,
  ): Promise<SocketReadAnswer> {
    const { res, answer } = captureAnswer(cap, take);
    const abandon = (): void => {
      if (!res.writableFinished) res.destroy();
    };
    if (signal?.aborted) abandon();
    signal?.addEventListener('abort', abandon, { once: true });
    const settled = async (): Promise<SocketReadAnswer> => {
      try {
        const a = await answer;
        return { status: a.status, headers: a.headers, body: a.body };
      } catch (e) {
        if (e instanceof AnswerTooLarge) return { fallback: e.message, tooLarge: true };
        // Cut. The controller was asked already: the page is told it failed, never sent to ask
        // again (a read may be consumed, as RepRapFirmware's rr_reply).
        const why = e instanceof Error ? e.message : String(e);
        return {
          status: 502,
          headers: { 'content-type': 'application/json; charset=utf-8', 'x-shopdeck-gateway': 'error' },
          body: Buffer.from(JSON.stringify({ error: `${m.name}: ${why}`, gateway: true })),
        };
      } finally {
        signal?.removeEventListener('abort', abandon);
      }
    };
    const t = splitTarget(rest);
    if ('error' in t) {
      sendJson(res, 400, { error: t.error });
      return settled();
    }
    const decision = classify(m, { method: 'GET', path: t.path, query: t.query });
    if (decision.command) {
      signal?.removeEventListener('abort', abandon);
      return { fallback: 'a command goes over HTTP' };
    }
    const w = who(from, false);
    const v = authorize(w, m, decision);
    if (!v.ok) {
      if (v.status === 403)
        record({
          type: 'refused',
          result: 'refused',
          machine: m.id,
          method: 'GET',
          path: scrub(auditTarget(t)),
          label: decision.label,
          address: clientAddress(from),
          source: 'gateway',
          user: w.principal?.name ?? 'nobody',
          onBehalfOf: w.principal?.onBehalfOf,
          role: decision.role,
          error: String(v.body.error),
        });
      sendJson(res, v.status, v.body);
      return settled();
    }
    const req = new IncomingMessage(new Socket());
    req.method = 'GET';
    req.url = rest;
    req.push(null);
    try {
      await sendUpstream(
        req,
        res,
        m,
        'GET',
        t,
        forwardRequestHeaders(browserHeaders),
        null,
        false,
        () => undefined,
      );
    } catch (e) {
      // The proxy threw before it could answer (its read slot is already released): the page
      // gets the gateway's error, as a browser over HTTP would (gateway.ts).
      if (!res.headersSent && !res.destroyed)
        sendJson(res, 500, { error: scrub(e instanceof Error ? e.message : String(e)), gateway: true });
      else res.destroy();
    }
    return settled();
  }

  return { proxy, watchRead, socketRead };
}

/** What a read sent over a page's read socket comes to (proxy-http.ts `socketRead`). */
export type SocketReadAnswer =
  | { status: number; headers: Record<string, string | string[]>; body: Buffer }
  /**
   * Not sent: the page sends it over HTTP (a command); or `tooLarge`: larger than the socket takes
   * (the page reads it over HTTP, where it streams).
   */
  | { fallback: string; tooLarge?: boolean };
