import type { TLSSocket } from 'node:tls';
import { CertificateChanged, connectPinned, PinFileError } from './tls-pin';
import { type IncomingMessage } from 'node:http';
import type { Duplex } from 'node:stream';
import { WebSocket, WebSocketServer, type RawData } from 'ws';
import type { AccessDecision } from '../src/fleet/access';
import type { Who } from './context';
import type { MachineEntry } from './machines';
import { redactFrame } from './redact';
import { bridgeSockets, DEFAULT_BRIDGE_LIMITS } from './ws-bridge';
import { crossSiteProblem } from './csrf';
import { clientAddress, forwardRequestHeaders, rejectUpgrade } from './http-util';
import { redact } from './machines';
import { auditTarget, splitTarget } from './paths';
import { bridgeSimSocket } from './sim-server';
import { holdSocket, type HeldSocket } from './held-session';
import type { SharedStreamDecl } from '../src/fleet/contract';
import { simUpstream, StreamHub, StreamHubs, streamQuery, wsUpstream } from './streams';
import type { GatewayContext } from './context';
import { unreachableReason } from './log';

export function createWsProxy(ctx: GatewayContext) {
  const {
    opts,
    timeoutMs,
    byId,
    secretsOf,
    openSockets,
    record,
    scrub,
    who,
    classify,
    authorize,
    simulatorFor,
    state,
    liveSockets,
    streams,
    patternsFor,
    pins,
    reachability,
    hintsOf,
  } = ctx;
  /** Bridged (one-to-one) controller sockets open now, per machine (`bridgedSockets.maxPerMachine`). */
  const bridgedOpen = new Map<string, number>();
  /** Counts a bridged socket of `id` in; the returned release counts it out (once). */
  const countBridged = (id: string): (() => void) => {
    bridgedOpen.set(id, (bridgedOpen.get(id) ?? 0) + 1);
    let done = false;
    return () => {
      if (done) return;
      done = true;
      const n = (bridgedOpen.get(id) ?? 1) - 1;
      if (n > 0) bridgedOpen.set(id, n);
      else bridgedOpen.delete(id);
    };
  };

  // ---------------------------------------------------------------- /machines (WebSocket)

  /**
   * Bridges an accepted browser socket to the controller's, with bounds (ws-bridge.ts), every
   * controller frame redacted, and the socket registered so that it closes when its user logs
   * out, expires, is removed or loses the role or machine (context.ts `revalidateSockets`).
   */
  function bridge(
    client: WebSocket,
    upstream: WebSocket,
    m: MachineEntry,
    w: Who,
    decision: AccessDecision,
  ): void {
    openSockets.add(upstream);
    const patterns = patternsFor(m);
    const b = bridgeSockets(client, upstream, {
      toClient: patterns.length ? (data, isBinary) => redactFrame(data, isBinary, patterns) : undefined,
      onClose: () => {
        unregister();
        openSockets.delete(upstream);
      },
    });
    const unregister = register(client, m, w, decision, (code, reason) => b.close(code, reason));
  }

  async function upgradeMachine(
    req: IncomingMessage,
    socket: Duplex,
    head: Buffer,
    id: string,
    rest: string,
  ): Promise<void> {
    const address = clientAddress(req);
    const refused = refuseUpgrade(ctx, req, socket, {
      machine: byId.has(id) ? id : undefined,
      path: scrub(rest.slice(0, 300)),
    });
    if (refused) return;
    const m = byId.get(id);
    if (!m) return rejectUpgrade(socket, 404, { error: `no machine "${id}" in the machines file` });
    const t = splitTarget(rest || '/');
    if ('error' in t) return rejectUpgrade(socket, 400, { error: t.error });
    const decision = classify(m, { method: 'GET', path: t.path, query: t.query, websocket: true });
    const w = who(req, decision.command);
    const auditPath = scrub(auditTarget(t));
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
    const fam = opts.families[m.kind];
    // Only the sockets the family declares exist here (the controller has room for a few): a
    // shared stream (one upstream per machine and declared path, whatever the viewers and query
    // strings) or a bridged socket (bounded per machine). Anything else is refused before any
    // connection to the controller, its session included.
    const declaredSocket = (): { shared: SharedStreamDecl } | { bridged: true } | null => {
      const s = hintsOf(m).sharing?.streams?.find((d) => d.matches(t.path));
      if (s) return { shared: s };
      return fam?.gateway?.bridgedSockets?.matches(t.path) ? { bridged: true } : null;
    };
    const noSocket = (): void =>
      rejectUpgrade(socket, 404, { error: `${m.name} has no socket at ${auditPath}`, gateway: true });
    const first = declaredSocket();
    if (!first) return noSocket();
    let streamQ = '';
    if ('shared' in first) {
      const q = streamQuery(first.shared, t.rawQuery);
      if (q instanceof Error) return rejectUpgrade(socket, 400, { error: q.message, gateway: true });
      streamQ = q;
    }
    const maxBridged = fam?.gateway?.bridgedSockets?.maxPerMachine ?? 0;
    if ('bridged' in first && (bridgedOpen.get(m.id) ?? 0) >= maxBridged)
      return rejectUpgrade(socket, 503, { error: `${m.name} has no free socket: try later`, gateway: true });
    // A socket the family classifies as a command is audited before it is opened (committed);
    // one that cannot be audited is not opened.
    const audit = decision.command
      ? ctx.beginCommand({
          ...base,
          commandId: decision.id,
          user: v.principal.name,
          onBehalfOf: v.principal.onBehalfOf,
        })
      : null;
    if (decision.command && !audit)
      return rejectUpgrade(socket, 503, {
        error: `${decision.label}: not opened, the audit log cannot be written (see the server log)`,
        gateway: true,
      });
    const audited = (r: { status?: number; error?: string }): void => {
      audit?.done(r.error ? r : { status: r.status ?? 101 });
    };
    const offered = String(req.headers['sec-websocket-protocol'] ?? '')
      .split(',')
      .map((s) => s.trim())
      .filter(Boolean);
    // Held controller session (held-session.ts): opened if needed; the browser's key is dropped
    // and the gateway's added to the upstream URL; the socket keeps the session alive.
    const held = await holdSocket(ctx, m);
    if (held && 'status' in held) {
      audited({ error: String(held.body.error ?? `answered ${held.status}`) });
      return rejectUpgrade(socket, held.status, held.body);
    }

    // The held session may have learned which API the controller speaks (a standalone Duet has no
    // socket at all): the declaration is asked again.
    const declared = declaredSocket();
    if (!declared || 'shared' in declared !== 'shared' in first) {
      audited({ error: 'no such socket' });
      return noSocket();
    }

    // A shared stream (streams.ts): one controller socket per machine, every viewer joins it.
    if ('shared' in declared) {
      const r = await joinHub(m, declared.shared, streamQ, held);
      if ('status' in r) {
        audited({ error: r.error });
        return rejectUpgrade(socket, r.status, {
          error: redact(r.error, secretsOf.get(m.id) ?? []),
          gateway: true,
        });
      }
      const wss = new WebSocketServer({
        noServer: true,
        clientTracking: false,
        perMessageDeflate: false,
        maxPayload: DEFAULT_BRIDGE_LIMITS.maxClientFrame,
      });
      if (socket.destroyed) {
        audited({ error: 'the browser went away' });
        return;
      }
      wss.handleUpgrade(req, socket, head, (client) => {
        audited({ status: 101 });
        register(client, m, w, decision, (code, reason) => client.close(code, reason));
        streams.noteJoin(m.id);
        r.add(client);
      });
      return;
    }

    if ((bridgedOpen.get(m.id) ?? 0) >= maxBridged) {
      audited({ error: 'no free socket' });
      return rejectUpgrade(socket, 503, { error: `${m.name} has no free socket: try later`, gateway: true });
    }
    if (m.simulated) {
      const sim = simulatorFor(m);
      if (!sim) {
        audited({ error: `no simulator for ${m.kind}` });
        return rejectUpgrade(socket, 503, { error: `no simulator for ${m.kind}` });
      }
      const release = countBridged(m.id);
      socket.once('close', release);
      const wss = new WebSocketServer({
        noServer: true,
        clientTracking: false,
        perMessageDeflate: false,
        maxPayload: DEFAULT_BRIDGE_LIMITS.maxClientFrame,
      });
      wss.handleUpgrade(req, socket, head, (client) => {
        audited({ status: 101 });
        client.once('close', release);
        const unregister = register(client, m, w, decision, (code, reason) => client.close(code, reason));
        held?.track(client); // held session: the simulator's socket uses the gateway's key
        const simTarget = held
          ? held.target(t.path, t.rawQuery)
          : t.path + (t.rawQuery ? `?${t.rawQuery}` : '');
        bridgeSimSocket(client, sim, simTarget, unregister);
      });
      return;
    }

    const headers = forwardRequestHeaders(req.headers);
    const release = countBridged(m.id);
    const o = await openControllerSocket(m, t.path, t.query, t.rawQuery, headers, offered, held);
    if (o.ok) o.upstream.once('close', release);
    else release();
    if (!o.ok) {
      audited({ error: o.error });
      return rejectUpgrade(socket, o.status, { error: o.error, ...(o.gateway ? { gateway: true } : {}) });
    }
    const { upstream, early, earlyClose } = o;
    const wss = new WebSocketServer({
      noServer: true,
      clientTracking: false,
      perMessageDeflate: false,
      maxPayload: DEFAULT_BRIDGE_LIMITS.maxClientFrame,
      handleProtocols: () => upstream.protocol || false,
    });
    if (socket.destroyed) {
      audited({ error: 'the browser went away' });
      upstream.close(1001, 'client went away');
      return;
    }
    wss.handleUpgrade(req, socket, head, (client) => {
      audited({ status: 101 });
      o.stopCollecting();
      const patterns = patternsFor(m);
      for (const e of early)
        client.send(patterns.length ? redactFrame(e.data, e.isBinary, patterns) : e.data, {
          binary: e.isBinary,
        });
      if (upstream.readyState !== WebSocket.OPEN) {
        // The controller closed (or broke the frame bound) before the browser was accepted.
        const c = earlyClose()?.code ?? 1011;
        client.close(c === 1006 || c === 1005 ? 1011 : c, earlyClose()?.reason ?? 'the controller closed');
        return;
      }
      bridge(client, upstream, m, w, decision);
      upstream.resume();
    });
  }

  /** A browser socket of a machine, closed when its user logs out or loses the role (context.ts). */
  function register(
    client: WebSocket,
    m: MachineEntry,
    w: Who,
    decision: AccessDecision,
    close: (code: number, reason: string) => void,
  ): () => void {
    openSockets.add(client);
    liveSockets.set(client, { machine: m.id, token: w.session?.token ?? null, needs: decision.role, close });
    const unregister = (): void => {
      openSockets.delete(client);
      liveSockets.delete(client);
    };
    client.once('close', unregister);
    return unregister;
  }

  type OpenedSocket =
    | {
        ok: true;
        upstream: WebSocket;
        /** Frames that came before anyone listened (bounded: the socket pauses). */
        early: Array<{ data: RawData; isBinary: boolean }>;
        earlyClose: () => { code: number; reason: string } | null;
        stopCollecting: () => void;
      }
    | { ok: false; status: number; error: string; gateway?: boolean };

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
        tlsSocket = await connectPinned({ machine: m, url: new URL(target), store: pins, timeoutMs });
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

  /**
   * The machine's shared hub for this stream: the open one, or a new one opened once. It is named
   * by the declared path and the declared query (`streamQuery`), never by the browser's spelling,
   * and that is what goes upstream: one controller socket per machine and declared stream.
   */
  async function joinHub(
    m: MachineEntry,
    decl: SharedStreamDecl,
    query: string,
    held: HeldSocket | null,
  ): Promise<StreamHub | { status: number; error: string }> {
    const path = decl.path;
    // Filtered here too, whatever the caller passed (streamQuery is idempotent): the key and the
    // upstream URL never hold a browser's own query string (one upstream per declared stream).
    const rawQuery = streamQuery(decl, query);
    if (rawQuery instanceof Error) return { status: 400, error: rawQuery.message };
    const key = StreamHubs.key(m.id, path, rawQuery);
    return streams.get(key, async () => {
      const patterns = patternsFor(m);
      const hubOpts = {
        toClient: patterns.length
          ? (data: Buffer, isBinary: boolean) => redactFrame(data, isBinary, patterns)
          : undefined,
        warn: (msg: string) => ctx.log.warn(`${m.id}: ${msg}`, { machine: m.id }),
        onEnd: () => streams.forget(key, hub),
      };
      let hub: StreamHub;
      if (m.simulated) {
        const sim = simulatorFor(m);
        if (!sim) return { status: 503, error: `no simulator for ${m.kind}` };
        const target = held ? held.target(path, rawQuery) : path + (rawQuery ? `?${rawQuery}` : '');
        const up = simUpstream(sim, target);
        if (!up) return { status: 404, error: 'no socket here' };
        held?.track(up.events);
        hub = new StreamHub(decl, up.socket, hubOpts);
        return { hub };
      }
      const o = await openControllerSocket(m, path, new URLSearchParams(rawQuery), rawQuery, {}, [], held);
      if (!o.ok) return { status: o.status, error: o.error };
      o.stopCollecting();
      hub = new StreamHub(decl, wsUpstream(o.upstream, o.early), hubOpts);
      o.upstream.resume();
      return { hub };
    });
  }

  /**
   * The gateway's watch holds a machine's shared stream open without a viewer (watch.ts) and
   * reads its frames. Throws when the stream cannot be opened now.
   */
  async function holdStream(
    m: MachineEntry,
    path: string,
    onFrame: (frame: string) => void,
    onEnd: () => void,
  ): Promise<() => void> {
    const decl = hintsOf(m).sharing?.streams?.find((d) => d.matches(path));
    if (!decl) throw new Error(`no shared stream at ${path}`);
    const held = await holdSocket(ctx, m);
    if (held && 'status' in held) throw new Error(String(held.body.error));
    const r = await joinHub(m, decl, '', held);
    if ('status' in r) throw new Error(r.error);
    const release = r.hold();
    const offFrame = r.onFrame(onFrame);
    const offEnd = r.onEnded(onEnd);
    return () => {
      offFrame();
      offEnd();
      release();
    };
  }

  return { upgradeMachine, holdStream };
}

/**
 * What every WebSocket upgrade the gateway takes must pass first (machine sockets, the page's read
 * socket): a gateway still running, an allowed Host, and an `Origin` of this console (another
 * site's page can open a WebSocket with the user's cookie; its try is audited as `refused`).
 * Answers the refusal on the socket and returns true when the upgrade may not go on.
 */
export function refuseUpgrade(
  ctx: GatewayContext,
  req: IncomingMessage,
  socket: Duplex,
  target: { machine?: string; path: string },
): boolean {
  socket.on('error', () => socket.destroy());
  if (ctx.state.closed) {
    rejectUpgrade(socket, 503, { error: 'the gateway is shutting down' });
    return true;
  }
  if (!ctx.hostAllowed(req)) {
    rejectUpgrade(socket, 403, { error: 'this host name is not allowed' });
    return true;
  }
  const crossSite = crossSiteProblem(req, 'websocket');
  if (!crossSite) return false;
  ctx.record({
    type: 'refused',
    result: 'refused',
    user: ctx.who(req, false).principal?.name ?? 'nobody',
    source: 'gateway',
    method: 'WS',
    machine: target.machine,
    path: target.path,
    address: clientAddress(req),
    error: crossSite,
  });
  rejectUpgrade(socket, 403, { error: `refused: ${crossSite}`, crossSite: true });
  return true;
}
