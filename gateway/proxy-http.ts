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
  forwardRequestHeaders,
  forwardResponseHeaders,
  readBody,
  sendJson,
} from './http-util';
import { redact, type MachineEntry } from './machines';
import { holdHttp, type HeldHttp } from './held-session';
import { auditTarget, splitTarget, type SplitTarget } from './paths';
import type { GatewayContext, Verdict } from './context';
import { crossSiteProblem } from './csrf';
import type { AccessDecision } from '../src/fleet/access';
import { unreachableReason } from './log';
import { captureAnswer } from './upstream-http';

const MAX_CLASSIFY_BODY = 1024 * 1024;
const MAX_SIM_BODY = 64 * 1024 * 1024;
/** The watch reads status answers: a few kB; a model (Duet) some tens. */
const WATCH_READ_MAX = 2 * 1024 * 1024;
export const READ_METHODS = new Set(['GET', 'HEAD', 'OPTIONS']);

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
      try {
        body = await readBody(req, MAX_CLASSIFY_BODY);
      } catch (e) {
        if (e instanceof BodyTooLarge) {
          sendJson(res, 413, { error: `request body larger than ${MAX_CLASSIFY_BODY} bytes` });
          return;
        }
        throw e;
      }
    }
    const decision = classify(m, { method, path: t.path, query: t.query, body: body?.toString('utf8') });
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
    const commandId =
      typeof req.headers['x-shopdeck-command'] === 'string'
        ? req.headers['x-shopdeck-command'].slice(0, 100)
        : undefined;
    const base = {
      machine: m.id,
      method,
      path: auditPath,
      commandId,
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
    const done = (r: { status?: number; error?: string }): void => {
      if (!isCommand) return;
      const ok = r.status !== undefined && r.status < 400;
      record({
        ...base,
        type: 'command',
        result: ok ? 'ok' : 'error',
        user: v.principal.name,
        onBehalfOf: v.principal.onBehalfOf,
        ...r,
      });
    };

    await sendUpstream(req, res, m, method, t, forwardRequestHeaders(req.headers), body, isCommand, done);
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
    done: (r: { status?: number; error?: string }) => void,
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
      { method, path: t.path, query, headers, isCommand, body },
      done,
    );
    if (held === 'answered') return;
    fam?.gateway?.injectSecrets?.({ method, path: t.path, headers, query }, m.secrets);
    const qs = query.toString() === before ? t.rawQuery : query.toString();
    const pathAndQuery = t.path + (qs ? `?${qs}` : '');

    const url = m.url;
    if (!m.simulated && !url) {
      sendJson(res, 502, { error: `machine ${m.id} has no url` });
      return;
    }
    // One upstream per machine (upstream-http.ts): identical reads shared, reads limited, commands
    // at once. `sink` is the browser's response, or a capture whose answer several browsers get.
    await ctx.upstream.send(
      { machine: m, req, res, method, path: t.path, query: t.query, pathAndQuery, headers, isCommand, held },
      (sink, agent, h) =>
        m.simulated || !url
          ? answerFromSimulator(req, sink, m, method, pathAndQuery, headers, body, done, h)
          : forward(req, sink, m, url, method, t.path, pathAndQuery, headers, body, done, h, agent),
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
    done: (r: { status?: number; error?: string }) => void,
    held: HeldHttp | null = null,
  ): Promise<void> {
    const sim = simulatorFor(m);
    if (!sim) {
      req.resume();
      sendJson(res, 503, { error: `no simulator for ${m.kind}: the family is not registered` });
      done({ status: 503 });
      return;
    }
    let body: Buffer | null = buffered;
    if (!body && method !== 'GET' && method !== 'HEAD') body = await readBody(req, MAX_SIM_BODY);
    const request = new Request(`http://${m.id}.sim${pathAndQuery}`, {
      method,
      headers,
      body: body && method !== 'GET' && method !== 'HEAD' ? new Uint8Array(body) : undefined,
    });
    let answer: Response;
    try {
      answer = await sim.fetch(request, pathAndQuery);
    } catch (e) {
      done({ error: e instanceof SimDropped ? 'connection dropped (simulated)' : String(e) });
      if (e instanceof SimDropped) res.destroy();
      else sendJson(res, 502, { error: `simulator failed: ${e instanceof Error ? e.message : String(e)}` });
      return;
    }
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

  /** The gateway's own failure (not the controller's answer): marked so the page can tell. */
  function gatewayError(res: ServerResponse, status: number, error: string): void {
    sendJson(res, status, { error, gateway: true });
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
    done: (r: { status?: number; error?: string }) => void,
    held: HeldHttp | null = null,
    /** For `http:` controllers (upstream-http.ts: the machine's reads may keep connections alive). */
    agent: http.Agent = httpAgent,
  ): Promise<void> {
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
          timeoutMs,
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
        const err = e instanceof Error ? e : new Error(String(e));
        const words = upstreamWords(m, err, false);
        upstreamFailed(m, err, false);
        req.resume();
        done({ error: words });
        gatewayError(res, 502, words);
        return;
      }
      if (res.destroyed) {
        tlsSocket.destroy();
        return;
      }
    }
    const socket = tlsSocket;
    const upstream = (isHttps ? https : http).request({
      protocol: target.protocol,
      hostname: target.hostname.replace(/^\[|\]$/g, ''),
      port: target.port || (isHttps ? 443 : 80),
      method,
      path: basePath + pathAndQuery,
      headers: { ...headers, host: target.host },
      ...(socket ? { createConnection: () => socket } : { agent }),
    });
    pending.add(upstream);
    let timedOut = false;
    let finished = false;
    /** The browser went away and the gateway ended the request: not the controller's doing. */
    let abandoned = false;
    const finish = (r: { status?: number; error?: string }): void => {
      if (finished) return;
      finished = true;
      pending.delete(upstream);
      done(r);
    };
    upstream.setTimeout(timeoutMs, () => {
      timedOut = true;
      upstream.destroy(new Error(`the controller did not answer within ${timeoutMs} ms`));
    });
    upstream.on('error', (e: Error & { code?: string }) => {
      const words = upstreamWords(m, e, timedOut);
      if (!abandoned && !ctx.state.closed) upstreamFailed(m, e, timedOut);
      finish({ error: words });
      if (!res.headersSent) gatewayError(res, timedOut ? 504 : 502, words);
      else res.destroy();
    });
    res.on('close', () => {
      if (res.writableFinished) return;
      abandoned = true;
      upstream.destroy();
    });
    upstream.on('response', (up) => {
      reachability.up(m.id);
      const status = up.statusCode ?? 502;
      // Held session (held-session.ts): a read whose key expired is sent once more with a new key.
      const again = (pq?: string): void =>
        void forward(req, res, m, target, method, path, pq ?? pathAndQuery, headers, body, done, null, agent);
      if (held?.retry(status, again, { request: upstream, response: up })) return;
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
          gatewayError(res, 502, `${m.name} answered with a redirect to another site: refused`);
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
        gatewayError(res, 502, `${m.name} sent an answer the gateway cannot check (Content-Encoding)`);
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
          finish({ status, error: `the answer was cut: ${redact(err.message, forms)}` });
        } else finish({ status });
      });
    });
    if (body) upstream.end(body);
    else if (method === 'GET' || method === 'HEAD') {
      req.resume();
      upstream.end();
    } else req.pipe(upstream);
  }

  /**
   * The gateway's own read of a machine (its watch, watch.ts): no browser behind it, so no user
   * and no role check, hence only what the family classifies as a read. It takes the browsers'
   * way (held session, secrets, sharing: within a window it costs the controller nothing).
   */
  async function watchRead(m: MachineEntry, pathAndQuery: string): Promise<{ status: number; body: string }> {
    const t = splitTarget(pathAndQuery);
    if ('error' in t) throw new Error(t.error);
    const decision = classify(m, { method: 'GET', path: t.path, query: t.query });
    if (decision.command) throw new Error(`${t.path} is a command: the watch only reads`);
    const req = new IncomingMessage(new Socket());
    req.method = 'GET';
    req.url = pathAndQuery;
    req.push(null);
    const { res, answer } = captureAnswer(WATCH_READ_MAX);
    await sendUpstream(req, res, m, 'GET', t, {}, null, false, () => undefined);
    const a = await answer;
    return { status: a.status, body: a.body.toString('utf8') };
  }

  return { proxy, watchRead };
}
