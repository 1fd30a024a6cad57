import { type IncomingMessage } from 'node:http';
import type { Duplex } from 'node:stream';
import { WebSocket, WebSocketServer, type RawData } from 'ws';
import { clientAddress, forwardRequestHeaders, rejectUpgrade, sameOrigin } from './http-util';
import { redact } from './machines';
import { splitTarget } from './paths';
import { bridgeSimSocket } from './sim-server';
import type { GatewayContext } from './context';

export function createWsProxy(ctx: GatewayContext) {
  const {
    opts,
    timeoutMs,
    byId,
    secretsOf,
    openSockets,
    hostAllowed,
    record,
    scrub,
    who,
    classify,
    authorize,
    simulatorFor,
    state,
  } = ctx;

  // ---------------------------------------------------------------- /machines (WebSocket)

  function bridge(client: WebSocket, upstream: WebSocket): void {
    openSockets.add(client);
    openSockets.add(upstream);
    const closeCode = (code: number): number | undefined =>
      (code >= 1000 && code <= 1003) || (code >= 1007 && code <= 1014) || (code >= 3000 && code <= 4999)
        ? code
        : undefined;
    const pass = (from: WebSocket, to: WebSocket) => {
      from.on('message', (data: RawData, isBinary: boolean) => {
        if (to.readyState === WebSocket.OPEN) to.send(data, { binary: isBinary });
      });
      from.on('close', (code: number, reason: Buffer) => {
        openSockets.delete(from);
        if (to.readyState === WebSocket.OPEN || to.readyState === WebSocket.CONNECTING) {
          const c = closeCode(code);
          if (code === 1006) to.terminate();
          else if (c === undefined) to.close();
          else to.close(c, reason.toString('utf8').slice(0, 120));
        }
      });
      from.on('error', () => {
        openSockets.delete(from);
        to.terminate();
      });
    };
    pass(client, upstream);
    pass(upstream, client);
  }

  async function upgradeMachine(
    req: IncomingMessage,
    socket: Duplex,
    head: Buffer,
    id: string,
    rest: string,
  ): Promise<void> {
    socket.on('error', () => socket.destroy());
    const address = clientAddress(req);
    if (state.closed) return rejectUpgrade(socket, 503, { error: 'the gateway is shutting down' });
    if (!hostAllowed(req)) return rejectUpgrade(socket, 403, { error: 'this host name is not allowed' });
    if (!sameOrigin(req)) return rejectUpgrade(socket, 403, { error: 'cross-site WebSocket refused' });
    const m = byId.get(id);
    if (!m) return rejectUpgrade(socket, 404, { error: `no machine "${id}" in the machines file` });
    const t = splitTarget(rest || '/');
    if ('error' in t) return rejectUpgrade(socket, 400, { error: t.error });
    const decision = classify(m, { method: 'GET', path: t.path, query: t.query, websocket: true });
    const w = who(req, decision.command);
    const auditPath = scrub(t.path + (t.rawQuery ? `?${t.rawQuery}` : ''));
    const base = {
      machine: m.id,
      method: 'WS',
      path: auditPath,
      label: decision.label,
      address,
      source: 'gateway' as const,
    };
    const v = authorize(w, m, decision);
    if (!v.ok) {
      if (v.status === 403 || decision.command) {
        record({
          ...base,
          type: 'refused',
          result: 'refused',
          user: w.principal?.name ?? 'nobody',
          role: decision.role,
          error: String(v.body.error),
        });
      }
      return rejectUpgrade(socket, v.status, v.body);
    }
    const audited = (r: { status?: number; error?: string }): void => {
      if (decision.command) {
        record({
          ...base,
          type: 'command',
          result: r.error ? 'error' : 'ok',
          user: v.principal.name,
          onBehalfOf: v.principal.onBehalfOf,
          ...r,
        });
      }
    };
    const fam = opts.families[m.kind];
    const offered = String(req.headers['sec-websocket-protocol'] ?? '')
      .split(',')
      .map((s) => s.trim())
      .filter(Boolean);

    if (m.simulated) {
      const sim = simulatorFor(m);
      if (!sim) return rejectUpgrade(socket, 503, { error: `no simulator for ${m.kind}` });
      const wss = new WebSocketServer({ noServer: true, clientTracking: false, perMessageDeflate: false });
      wss.handleUpgrade(req, socket, head, (client) => {
        openSockets.add(client);
        audited({ status: 101 });
        bridgeSimSocket(client, sim, t.path + (t.rawQuery ? `?${t.rawQuery}` : ''), () =>
          openSockets.delete(client),
        );
      });
      return;
    }

    let baseUrl: string;
    if (m.wsUrl) {
      baseUrl = `${m.wsUrl.protocol}//${m.wsUrl.host}${m.wsUrl.pathname.replace(/\/+$/, '')}`;
    } else if (m.url) {
      const port = fam?.gateway?.defaultWsPort;
      const host = port ? `${m.url.hostname}:${port}` : m.url.host;
      baseUrl = `${m.url.protocol === 'https:' ? 'wss:' : 'ws:'}//${host}${m.url.pathname.replace(/\/+$/, '')}`;
    } else {
      return rejectUpgrade(socket, 502, { error: `machine ${m.id} has no url` });
    }
    const headers = forwardRequestHeaders(req.headers);
    const query = new URLSearchParams(t.query);
    const before = query.toString();
    fam?.gateway?.injectSecrets?.({ method: 'GET', path: t.path, headers, query }, m.secrets);
    const qs = query.toString() === before ? t.rawQuery : query.toString();
    const target = baseUrl + t.path + (qs ? `?${qs}` : '');
    const forms = secretsOf.get(m.id) ?? [];
    const upstream = new WebSocket(target, offered, {
      headers,
      rejectUnauthorized: false,
      handshakeTimeout: timeoutMs,
      perMessageDeflate: false,
      followRedirects: false,
    });
    openSockets.add(upstream);
    const early: Array<{ data: RawData; isBinary: boolean }> = [];
    const collect = (data: RawData, isBinary: boolean): void => {
      early.push({ data, isBinary });
    };
    upstream.on('message', collect);
    const fail = (status: number, error: string): void => {
      openSockets.delete(upstream);
      audited({ error });
      rejectUpgrade(socket, status, { error: redact(error, forms) });
    };
    upstream.once('unexpected-response', (_r, resp) => {
      upstream.removeAllListeners('error');
      upstream.on('error', () => undefined);
      fail(502, `the controller refused the WebSocket (HTTP ${resp.statusCode ?? '?'})`);
      resp.resume();
      upstream.terminate();
    });
    upstream.once('error', (e) => {
      if (upstream.readyState !== WebSocket.OPEN) {
        const timeout = /timed out|timeout/i.test(e.message);
        fail(timeout ? 504 : 502, `cannot open the controller's WebSocket: ${e.message}`);
      }
    });
    upstream.once('open', () => {
      const wss = new WebSocketServer({
        noServer: true,
        clientTracking: false,
        perMessageDeflate: false,
        handleProtocols: () => upstream.protocol || false,
      });
      if (socket.destroyed) {
        upstream.close(1001, 'client went away');
        return;
      }
      wss.handleUpgrade(req, socket, head, (client) => {
        audited({ status: 101 });
        upstream.off('message', collect);
        for (const e of early) client.send(e.data, { binary: e.isBinary });
        bridge(client, upstream);
      });
    });
  }

  return upgradeMachine;
}
