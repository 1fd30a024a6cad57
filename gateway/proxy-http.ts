import http, { type IncomingMessage, type ServerResponse } from 'node:http';
import https from 'node:https';
import { SimDropped } from '../src/fleet/sim';
import {
  BodyTooLarge,
  clientAddress,
  forwardRequestHeaders,
  forwardResponseHeaders,
  readBody,
  sendJson,
} from './http-util';
import { redact, type MachineEntry } from './machines';
import { splitTarget } from './paths';
import type { GatewayContext } from './context';

const MAX_CLASSIFY_BODY = 1024 * 1024;
const MAX_SIM_BODY = 64 * 1024 * 1024;
const MAX_REDACT_BODY = 2 * 1024 * 1024;
export const READ_METHODS = new Set(['GET', 'HEAD', 'OPTIONS']);
const TEXTISH =
  /^(text\/|application\/(json|xml|javascript|x-www-form-urlencoded|problem\+json)|[^;]*\+(json|xml))/i;

/**
 * A redirect to the controller itself (absolute URL or absolute path) becomes the same place
 * under `/machines/<id>`, so the browser stays on the console's origin. Relative redirects
 * already resolve under `/machines/<id>`; redirects elsewhere are left alone.
 */
export function rewriteLocation(location: string, target: URL, id: string): string {
  const basePath = target.pathname.replace(/\/+$/, '');
  const absolute = /^[a-z][a-z0-9+.-]*:/i.test(location) || location.startsWith('//');
  if (!absolute && !location.startsWith('/')) return location;
  let u: URL;
  try {
    u = new URL(location, target.origin);
  } catch {
    return location;
  }
  if (u.origin !== target.origin) return location;
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
    httpsAgent,
    record,
    scrub,
    who,
    classify,
    authorize,
    simulatorFor,
  } = ctx;

  // ---------------------------------------------------------------- /machines (HTTP)

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
    const w = who(req, isCommand);
    const auditPath = scrub(t.path + (t.rawQuery ? `?${t.rawQuery}` : ''));
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

    const headers = forwardRequestHeaders(req.headers);
    const query = new URLSearchParams(t.query);
    const before = query.toString();
    fam?.gateway?.injectSecrets?.({ method, path: t.path, headers, query }, m.secrets);
    const qs = query.toString() === before ? t.rawQuery : query.toString();
    const pathAndQuery = t.path + (qs ? `?${qs}` : '');

    if (m.simulated) {
      await answerFromSimulator(req, res, m, method, pathAndQuery, headers, body, done);
      return;
    }
    if (!m.url) {
      sendJson(res, 502, { error: `machine ${m.id} has no url` });
      return;
    }
    forward(req, res, m, m.url, method, pathAndQuery, headers, body, done);
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
    const out: Record<string, string> = {};
    answer.headers.forEach((value, key) => {
      const k = key.toLowerCase();
      if (
        k !== 'set-cookie' &&
        k !== 'content-length' &&
        k !== 'www-authenticate' &&
        k !== 'content-encoding'
      )
        out[k] = value;
    });
    const buf = Buffer.from(await answer.arrayBuffer());
    res.writeHead(answer.status, { ...out, 'Content-Length': String(buf.length) });
    res.end(method === 'HEAD' ? undefined : buf);
    done({ status: answer.status });
  }

  function forward(
    req: IncomingMessage,
    res: ServerResponse,
    m: MachineEntry,
    target: URL,
    method: string,
    pathAndQuery: string,
    headers: Record<string, string>,
    body: Buffer | null,
    done: (r: { status?: number; error?: string }) => void,
  ): void {
    const isHttps = target.protocol === 'https:';
    const basePath = target.pathname.replace(/\/+$/, '');
    const forms = secretsOf.get(m.id) ?? [];
    if (body) headers['content-length'] = String(body.length);
    else if (req.headers['content-length']) headers['content-length'] = req.headers['content-length'];
    else if (req.headers['transfer-encoding']) headers['transfer-encoding'] = 'chunked';
    const upstream = (isHttps ? https : http).request({
      protocol: target.protocol,
      hostname: target.hostname.replace(/^\[|\]$/g, ''),
      port: target.port || (isHttps ? 443 : 80),
      method,
      path: basePath + pathAndQuery,
      headers: { ...headers, host: target.host },
      agent: isHttps ? httpsAgent : httpAgent,
    });
    pending.add(upstream);
    let timedOut = false;
    let finished = false;
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
    upstream.on('error', (e) => {
      const msg = redact(e.message, forms);
      finish({ error: msg });
      if (!res.headersSent) {
        sendJson(res, timedOut ? 504 : 502, {
          error: timedOut ? `timeout: ${msg}` : `cannot reach the controller of ${m.id}: ${msg}`,
        });
      } else {
        res.destroy();
      }
    });
    res.on('close', () => {
      if (!res.writableFinished) upstream.destroy();
    });
    upstream.on('response', (up) => {
      const status = up.statusCode ?? 502;
      const outHeaders = forwardResponseHeaders(up.headers);
      for (const [k, v] of Object.entries(outHeaders)) {
        outHeaders[k] = Array.isArray(v) ? v.map((x) => redact(x, forms)) : redact(v, forms);
      }
      const location = outHeaders.location;
      if (typeof location === 'string') outHeaders.location = rewriteLocation(location, target, m.id);
      const type = String(up.headers['content-type'] ?? '');
      const encoded = up.headers['content-encoding'] && up.headers['content-encoding'] !== 'identity';
      const length = Number(up.headers['content-length'] ?? NaN);
      const check =
        forms.length > 0 && !encoded && (type === '' || TEXTISH.test(type)) && !(length > MAX_REDACT_BODY);
      if (!check) {
        res.writeHead(
          status,
          up.headers['content-length']
            ? { ...outHeaders, 'content-length': up.headers['content-length'] }
            : outHeaders,
        );
        up.pipe(res);
        up.on('end', () => finish({ status }));
        up.on('error', (e) => finish({ status, error: redact(e.message, forms) }));
        return;
      }
      const chunks: Buffer[] = [];
      let size = 0;
      let streaming = false;
      up.on('data', (c: Buffer) => {
        if (streaming) return;
        size += c.length;
        chunks.push(c);
        if (size > MAX_REDACT_BODY) {
          // Too big to check: send what we have (checked) and stream the rest as is.
          streaming = true;
          up.pause();
          res.writeHead(status, outHeaders);
          res.write(redact(Buffer.concat(chunks).toString('utf8'), forms));
          up.pipe(res);
          up.resume();
        }
      });
      up.on('end', () => {
        if (!streaming) {
          const text = Buffer.concat(chunks);
          const clean = Buffer.from(redact(text.toString('utf8'), forms), 'utf8');
          const same = clean.length === text.length && clean.equals(text);
          res.writeHead(status, {
            ...outHeaders,
            'content-length': String(same ? text.length : clean.length),
          });
          res.end(same ? text : clean);
        }
        finish({ status });
      });
      up.on('error', (e) => finish({ status, error: redact(e.message, forms) }));
    });
    if (body) upstream.end(body);
    else if (method === 'GET' || method === 'HEAD') {
      req.resume();
      upstream.end();
    } else req.pipe(upstream);
  }

  return proxy;
}
