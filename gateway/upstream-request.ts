import http from 'node:http';
import type { UpstreamAnswer } from '../src/fleet/contract';
import { unreachableReason } from './log';
import { redact, type MachineEntry } from './machines';
import type { AuditService, ConfigService, LinksService, MachinesService, SecretsService } from './services';
import { connectPinned } from './tls-pin';

/** Answers of the gateway's own requests are read up to this. */
const MAX_ANSWER = 1024 * 1024;

/** What `upstreamRequest` uses of the gateway. */
export type UpstreamRequestHost = Pick<ConfigService, 'timeoutMs' | 'state'> &
  Pick<MachinesService, 'simulatorFor'> &
  Pick<LinksService, 'pins' | 'httpAgent' | 'pending' | 'reachability'> &
  Pick<AuditService, 'record'> &
  Pick<SecretsService, 'secretsOf'>;

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
