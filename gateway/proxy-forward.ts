import http, { type IncomingMessage, type ServerResponse } from 'node:http';
import https from 'node:https';
import type { TLSSocket } from 'node:tls';
import { pipeline, type Transform } from 'node:stream';
import { SimDropped, splitPath } from '../src/fleet/sim';
import { safeAnswerHeaders } from './answer-headers';
import type { CommandWatch, Done } from './command-watch';
import type { GatewayContext } from './context';
import type { HeldHttp } from './held-session';
import { forwardResponseHeaders, markStreamedBody, readBody, sendJson } from './http-util';
import { unreachableReason } from './log';
import { redact, type MachineEntry } from './machines';
import { createRedactor, decoderFor, redactBytes } from './redact';
import { CertificateChanged, connectPinned, PinFileError } from './tls-pin';
import { sendAgain, trustEntry } from './tls-pool';

/**
 * The last leg of `/machines/<id>/*` over HTTP (proxy-http.ts): an authorized request sent to the
 * controller (pinned TLS, redirects kept on the console, the answer decoded and redacted) or
 * answered by its simulator (or a serial board's bridge) under the same rules.
 */

const MAX_SIM_BODY = 64 * 1024 * 1024;

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

export function createForwarder(ctx: GatewayContext) {
  const {
    opts,
    timeoutMs,
    secretsOf,
    pending,
    httpAgent,
    record,
    patternsFor,
    pins,
    tlsPools,
    hintsOf,
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
    /** An `https:` read sent again after its kept connection was found closed: a new connection. */
    fresh = false,
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
    /**
     * A read's kept pinned connections (tls-pool.ts) when the family keeps connections
     * (`sharing.keepAlive`); a command, or any request otherwise, gets a connection of its own.
     */
    let pool: http.Agent | null = null;
    if (isHttps) {
      // The controller's certificate is checked (configured fingerprint or trust on first use)
      // before one byte of the request, and so before any secret, is written (tls-pin.ts); a
      // kept connection only while the pin it was checked against is still the one in force.
      try {
        if (!watch && !fresh && hintsOf(m).sharing?.keepAlive === true) pool = tlsPools.agentFor(m, target);
        else
          tlsSocket = await connectPinned({
            machine: m,
            url: target,
            store: pins,
            // A command's deadline ends the handshake too (its own 504 comes first: a little later).
            timeoutMs: Math.min(timeoutMs, (watch?.remaining() ?? Number.POSITIVE_INFINITY) + 100),
            onTrust: (r) => record(trustEntry(m, r)),
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
      if (tlsSocket && (res.destroyed || watch?.stopped)) {
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
        ...(socket ? { createConnection: () => socket } : { agent: pool ?? agent }),
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
    let answered = false;
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
      // A read whose kept connection the controller had closed: once more, on a new connection.
      if (pool && !answered && !timedOut && !abandoned && !res.destroyed && sendAgain(upstream, e, method)) {
        letGo();
        resend(pathAndQuery, held, null, true);
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
    /** This request is sent again by a forward of its own: this one lets go of it. */
    const letGo = (): void => {
      finished = true;
      pending.delete(upstream);
      unwatch();
      res.off('close', onBrowserGone);
    };
    /** The same request forwarded again: a new key (`held` null), or a new connection (`fresh`). */
    const resend = (pq: string, h: HeldHttp | null, w: CommandWatch | null, fresh: boolean): void =>
      void forward(req, res, m, target, method, path, pq, headers, body, done, h, agent, w, fresh);
    upstream.on('response', (up) => {
      answered = true;
      reachability.up(m.id);
      const status = up.statusCode ?? 502;
      // Held session (held-session.ts): a read whose key expired is sent once more with a new key.
      const again = (pq?: string): void => resend(pq ?? pathAndQuery, null, watch, false);
      if (held?.retry(status, again, { request: upstream, response: up })) {
        // Sent again with a new key (a forward of its own): this one lets go of the response.
        letGo();
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

  return { forward, answerFromSimulator, gatewayError };
}
