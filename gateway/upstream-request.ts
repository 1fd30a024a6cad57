import http from 'node:http';
import https from 'node:https';
import type { TLSSocket } from 'node:tls';
import type { UpstreamAnswer } from '../src/fleet/contract';
import { unreachableReason } from './log';
import { redact, type MachineEntry } from './machines';
import type { AuditService, ConfigService, LinksService, MachinesService, SecretsService } from './services';
import { connectPinned } from './tls-pin';
import { sendAgain, trustEntry } from './tls-pool';

/** Answers of the gateway's own requests are read up to this. */
const MAX_ANSWER = 1024 * 1024;

/** What `upstreamRequest` uses of the gateway. */
export type UpstreamRequestHost = Pick<ConfigService, 'timeoutMs' | 'state'> &
  Pick<MachinesService, 'simulatorFor' | 'hintsOf'> &
  Pick<LinksService, 'pins' | 'tlsPools' | 'httpAgent' | 'pending' | 'reachability'> &
  Pick<AuditService, 'record'> &
  Pick<SecretsService, 'secretsOf'>;

function flatHeaders(h: http.IncomingHttpHeaders): Record<string, string> {
  const out: Record<string, string> = {};
  for (const [k, v] of Object.entries(h))
    if (v !== undefined) out[k.toLowerCase()] = Array.isArray(v) ? v.join(', ') : v;
  return out;
}

/**
 * One request of the gateway's own to a machine: its controller (through the same agent and TLS
 * pinning as forwarded requests: an `https:` read on the machine's kept pinned connections when
 * its family keeps connections, tls-pool.ts) or its in-process simulator. `detached`: not on the
 * shared agent nor the pool, not in `pending` (requests sent while the gateway closes).
 */
export async function upstreamRequest(
  ctx: UpstreamRequestHost,
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
  const keep =
    (method === 'GET' || method === 'HEAD') && !opts.detached && ctx.hintsOf(m).sharing?.keepAlive === true;
  /** `fresh`: a read sent again after its kept connection was found closed (a new connection). */
  const send = async (fresh: boolean): Promise<UpstreamAnswer> => {
    const pool = isHttps && keep && !fresh ? ctx.tlsPools.agentFor(m, target) : null;
    const socket =
      isHttps && !pool
        ? await connectPinned({
            machine: m,
            url: target,
            store: ctx.pins,
            timeoutMs: ctx.timeoutMs,
            onTrust: (r) => ctx.record(trustEntry(m, r)),
          })
        : null;
    return exchange(ctx, m, target, method, pathAndQuery, headers, { ...opts, body }, socket, pool, () =>
      send(true),
    );
  };
  return send(false);
}

/** The request itself, on `socket` (a pinned one of its own), `pool` (kept pinned ones) or an agent. */
function exchange(
  ctx: UpstreamRequestHost,
  m: MachineEntry,
  target: URL,
  method: string,
  pathAndQuery: string,
  headers: Record<string, string>,
  opts: { detached?: boolean; body?: string | Buffer; onData?: (chunk: Uint8Array) => boolean },
  socket: TLSSocket | null,
  pool: http.Agent | null,
  again: () => Promise<UpstreamAnswer>,
): Promise<UpstreamAnswer> {
  const { body, onData } = opts;
  const isHttps = target.protocol === 'https:';
  return new Promise<UpstreamAnswer>((resolve, reject) => {
    const req = (isHttps ? https : http).request({
      protocol: target.protocol,
      hostname: target.hostname.replace(/^\[|\]$/g, ''),
      port: target.port || (isHttps ? 443 : 80),
      method,
      path: target.pathname.replace(/\/+$/, '') + pathAndQuery,
      headers: {
        ...headers,
        host: target.host,
        ...(body !== undefined ? { 'content-length': String(Buffer.byteLength(body)) } : {}),
      },
      ...(socket
        ? { createConnection: () => socket }
        : { agent: pool ?? (opts.detached ? false : ctx.httpAgent) }),
    });
    if (!opts.detached) ctx.pending.add(req);
    const settle = (): void => {
      ctx.pending.delete(req);
    };
    req.setTimeout(ctx.timeoutMs, () =>
      req.destroy(new Error(`the controller did not answer within ${ctx.timeoutMs} ms`)),
    );
    let answered = false;
    req.on('error', (e: Error & { code?: string }) => {
      settle();
      // A read whose kept connection the controller had closed: once more, on a new connection.
      if (pool && !answered && sendAgain(req, e, method)) {
        again().then(resolve, reject);
        return;
      }
      const reason = opts.detached || ctx.state.closed ? null : unreachableReason(e, false);
      if (reason) ctx.reachability.down(m.id, reason, redact(e.message, ctx.secretsOf.get(m.id) ?? []));
      reject(e);
    });
    req.on('response', (res) => {
      answered = true;
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
