import { type IncomingMessage } from 'node:http';
import type { Duplex } from 'node:stream';
import { WebSocket, WebSocketServer } from 'ws';
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
import { holdSocket } from './held-session';
import type { SharedStreamDecl } from '../src/fleet/contract';
import { streamQuery } from './stream-hubs';
import type { GatewayContext } from './context';
import { createSocketOpener } from './controller-socket';
import { createStreamJoin } from './stream-join';

export function createWsProxy(ctx: GatewayContext) {
  const {
    opts,
    byId,
    secretsOf,
    openSockets,
    record,
    scrub,
    who,
    classify,
    authorize,
    simulatorFor,
    liveSockets,
    streams,
    patternsFor,
    hintsOf,
  } = ctx;
  // Controller sockets (controller-socket.ts) and shared streams (stream-join.ts).
  const openControllerSocket = createSocketOpener(ctx);
  const { joinHub, holdStream } = createStreamJoin(ctx, openControllerSocket);
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
