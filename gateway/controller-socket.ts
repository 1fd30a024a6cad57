import type { TLSSocket } from 'node:tls';
import { WebSocket, type RawData } from 'ws';
import type { GatewayContext } from './context';
import type { HeldSocket } from './held-session';
import { unreachableReason } from './log';
import { redact, type MachineEntry } from './machines';
import { CertificateChanged, connectPinned, PinFileError } from './tls-pin';
import { trustEntry } from './tls-pool';
import { DEFAULT_BRIDGE_LIMITS } from './ws-bridge';

export type OpenedSocket =
  | {
      ok: true;
      upstream: WebSocket;
      /** Frames that came before anyone listened (bounded: the socket pauses). */
      early: Array<{ data: RawData; isBinary: boolean }>;
      earlyClose: () => { code: number; reason: string } | null;
      stopCollecting: () => void;
    }
  | { ok: false; status: number; error: string; gateway?: boolean };

/** Opens a controller's WebSocket: for a bridged browser socket (proxy-ws.ts) or a shared stream. */
export function createSocketOpener(ctx: GatewayContext) {
  const { opts, timeoutMs, secretsOf, openSockets, state, pins, reachability, record } = ctx;

  /**
   * Opens the controller's WebSocket for `path?query` (the held session's key and the family's
   * secrets added, the certificate checked first for wss). Resolves once it is open, or with
   * the refusal for the browser (words without the controller's address or secrets).
   */
  async function openControllerSocket(
    m: MachineEntry,
    path: string,
    parsed: URLSearchParams,
    rawQuery: string,
    headers: Record<string, string>,
    offered: string[],
    held: HeldSocket | null,
  ): Promise<OpenedSocket> {
    const fam = opts.families[m.kind];
    let baseUrl: string;
    if (m.wsUrl) {
      baseUrl = `${m.wsUrl.protocol}//${m.wsUrl.host}${m.wsUrl.pathname.replace(/\/+$/, '')}`;
    } else if (m.url) {
      const port = fam?.gateway?.defaultWsPort;
      const host = port ? `${m.url.hostname}:${port}` : m.url.host;
      baseUrl = `${m.url.protocol === 'https:' ? 'wss:' : 'ws:'}//${host}${m.url.pathname.replace(/\/+$/, '')}`;
    } else {
      return { ok: false, status: 502, error: `machine ${m.id} has no url` };
    }
    const query = new URLSearchParams(parsed);
    const before = query.toString();
    held?.apply(query, headers); // held session (held-session.ts): the gateway's key, not the browser's
    fam?.gateway?.injectSecrets?.({ method: 'GET', path, headers, query }, m.secrets);
    const qs = query.toString() === before ? rawQuery : query.toString();
    const target = baseUrl + path + (qs ? `?${qs}` : '');
    const forms = secretsOf.get(m.id) ?? [];
    let tlsSocket: TLSSocket | null = null;
    if (target.startsWith('wss:')) {
      // The certificate is checked before the handshake (and any secret in it) is sent.
      try {
        tlsSocket = await connectPinned({
          machine: m,
          url: new URL(target),
          store: pins,
          timeoutMs,
          // Trusted on first use by a socket: audited as over HTTP.
          onTrust: (r) => record(trustEntry(m, r)),
        });
      } catch (e) {
        const msg =
          e instanceof CertificateChanged || e instanceof PinFileError ? e.message : `cannot reach ${m.name}`;
        const reason = unreachableReason(e as Error & { code?: string }, false);
        if (reason)
          reachability.down(m.id, reason, redact(e instanceof Error ? e.message : String(e), forms));
        return { ok: false, status: 502, error: msg, gateway: true };
      }
    }
    const pinned = tlsSocket;
    const upstream = new WebSocket(target, offered, {
      headers,
      ...(pinned ? { createConnection: () => pinned } : {}),
      handshakeTimeout: timeoutMs,
      perMessageDeflate: false,
      followRedirects: false,
      maxPayload: DEFAULT_BRIDGE_LIMITS.maxUpstreamFrame,
    });
    held?.track(upstream); // held session: open while this socket is
    openSockets.add(upstream);
    upstream.once('close', () => openSockets.delete(upstream));
    const early: Array<{ data: RawData; isBinary: boolean }> = [];
    // Frames that arrive before the browser's socket is accepted: bounded like the rest.
    let earlyBytes = 0;
    const collect = (data: RawData, isBinary: boolean): void => {
      earlyBytes += Array.isArray(data) ? data.reduce((n, d) => n + d.length, 0) : data.byteLength;
      if (earlyBytes > DEFAULT_BRIDGE_LIMITS.highWaterBytes) upstream.pause();
      early.push({ data, isBinary });
    };
    upstream.on('message', collect);
    let earlyClose: { code: number; reason: string } | null = null;
    upstream.once('close', (code: number, reason: Buffer) => {
      earlyClose = { code, reason: reason.toString('utf8').slice(0, 120) };
    });
    return new Promise<OpenedSocket>((resolve) => {
      let settled = false;
      const fail = (status: number, error: string): void => {
        if (settled) return;
        settled = true;
        openSockets.delete(upstream);
        resolve({ ok: false, status, error: redact(error, forms) });
      };
      upstream.once('unexpected-response', (_r, resp) => {
        reachability.up(m.id); // it answered, with something else than a WebSocket
        upstream.removeAllListeners('error');
        upstream.on('error', () => undefined);
        fail(502, `the controller refused the WebSocket (HTTP ${resp.statusCode ?? '?'})`);
        resp.resume();
        upstream.terminate();
      });
      upstream.on('error', (e) => {
        // After the handshake, errors are the bridge's or the hub's business (they close both
        // sides): never write an HTTP answer on a socket that may already be upgraded.
        if (!settled && upstream.readyState !== WebSocket.OPEN) {
          const timeout = /timed out|timeout/i.test(e.message);
          const reason = state.closed ? null : unreachableReason(e as Error & { code?: string }, false);
          if (reason) reachability.down(m.id, reason, redact(e.message, forms));
          fail(timeout ? 504 : 502, `cannot open the controller's WebSocket: ${e.message}`);
        }
      });
      upstream.once('open', () => {
        if (settled) return;
        settled = true;
        reachability.up(m.id);
        resolve({
          ok: true,
          upstream,
          early,
          earlyClose: () => earlyClose,
          stopCollecting: () => upstream.off('message', collect),
        });
      });
    });
  }

  return openControllerSocket;
}
