import net from 'node:net';

/**
 * A TCP fault proxy for tests: listens on 127.0.0.1 and forwards every connection to a target
 * port, byte for byte, until told to misbehave. The mode can be switched at any time and applies
 * to the connections already open as well as to new ones:
 *
 * - `pass`: forward.
 * - `refuse`: the port is closed (connect → ECONNREFUSED); open connections are reset, as a
 *   controller that crashed or was switched off.
 * - `silent`: a network that delivers nothing: connections are accepted and read, nothing is
 *   forwarded either way, nothing is closed. Data is held the way TCP holds it: when the mode
 *   changes, the data held on a connection that was established before the silence is delivered
 *   (the kernel's retransmission after the partition heals), also when its sender closed it
 *   gracefully (FIN) meanwhile; a sender that reset it (RST) loses what it sent. A connection that
 *   was accepted during the silence never completed its handshake on a real network: if its
 *   client goes away before the silence ends, nothing of it ever reaches the target.
 * - `reset`: every open connection is reset (RST), and new ones are reset as soon as accepted.
 * - `latency`: every chunk is delayed by `ms`, each way, order kept.
 * - `truncate`: the first `bytes` of each answer (target → client data following client data) are
 *   forwarded, then the connection is closed (`then: 'close'`) or kept open with nothing more
 *   forwarded (`then: 'hold'`). Client → target data passes.
 * - `restart`: everything is reset, the port refuses for `downMs`, then the mode is `pass` again.
 */

export type FaultMode =
  | { kind: 'pass' }
  | { kind: 'refuse' }
  | { kind: 'silent' }
  | { kind: 'reset' }
  | { kind: 'latency'; ms: number }
  | { kind: 'truncate'; bytes: number; then: 'close' | 'hold' }
  | { kind: 'restart'; downMs: number };

export interface FaultProxyStats {
  /** Connections accepted (not counting those reset on accept in `reset` mode). */
  connections: number;
  /** Connections reset on accept (`reset` mode). */
  resetOnAccept: number;
  /** Connections open now. */
  open: number;
  /** Bytes delivered client → target. */
  bytesUp: number;
  /** Bytes delivered target → client. */
  bytesDown: number;
  /** Bytes held by a silence and delivered when it ended. */
  heldDelivered: number;
  /** Bytes held by a silence and dropped (their sender reset the connection, or never connected). */
  heldDropped: number;
  /** Clients of established connections that closed gracefully (FIN) while data of theirs was held. */
  finWhileHeld: number;
  /** Clients that reset (RST) while data of theirs was held. */
  resetWhileHeld: number;
  /** Answers cut by `truncate`. */
  truncated: number;
}

export interface FaultProxy {
  readonly host: string;
  readonly port: number;
  /** `http://127.0.0.1:<port>` (or another scheme: `ws`). */
  url(scheme?: string): string;
  readonly mode: FaultMode;
  /** Switch the mode; resolves once the port is closed or listening again as the mode wants. */
  set(mode: FaultMode): Promise<void>;
  stats(): FaultProxyStats;
  resetStats(): void;
  close(): Promise<void>;
}

export interface FaultProxyOptions {
  targetPort: number;
  targetHost?: string;
  /** 0 (default): any free port. */
  port?: number;
}

type Dir = 'up' | 'down';

interface Pipe {
  queue: Array<{ chunk: Buffer; due: number }>;
  /** The sender ended (FIN): end the receiver once the queue is delivered. */
  ended: boolean;
  timer: ReturnType<typeof setTimeout> | null;
}

interface Conn {
  client: net.Socket;
  upstream: net.Socket | null;
  /** Accepted during a silence: no upstream yet (its handshake would not have completed). */
  bornSilent: boolean;
  /** Bytes of the current answer forwarded (truncate). */
  answerBytes: number;
  /** Truncated: nothing more goes to the client (`hold`), or it is being closed (`close`). */
  cut: boolean;
  up: Pipe;
  down: Pipe;
  closed: boolean;
  /** Reset by its client: what it sent and is still held is lost. */
  clientReset: boolean;
}

const newPipe = (): Pipe => ({ queue: [], ended: false, timer: null });

const zeroStats = (): FaultProxyStats => ({
  connections: 0,
  resetOnAccept: 0,
  open: 0,
  bytesUp: 0,
  bytesDown: 0,
  heldDelivered: 0,
  heldDropped: 0,
  finWhileHeld: 0,
  resetWhileHeld: 0,
  truncated: 0,
});

function queuedBytes(p: Pipe): number {
  return p.queue.reduce((n, q) => n + q.chunk.length, 0);
}

export async function startFaultProxy(o: FaultProxyOptions): Promise<FaultProxy> {
  const host = '127.0.0.1';
  const targetHost = o.targetHost ?? '127.0.0.1';
  const conns = new Set<Conn>();
  let stats = zeroStats();
  let mode: FaultMode = { kind: 'pass' };
  let server: net.Server | null = null;
  let port = o.port ?? 0;
  let restartTimer: ReturnType<typeof setTimeout> | null = null;
  let closed = false;
  /** Bumped by every `set`: a restart's timer of an earlier `set` does nothing. */
  let generation = 0;

  const silent = (): boolean => mode.kind === 'silent';

  function destroy(c: Conn, how: 'reset' | 'close'): void {
    if (c.closed) return;
    c.closed = true;
    conns.delete(c);
    for (const p of [c.up, c.down]) {
      if (p.timer) clearTimeout(p.timer);
      p.timer = null;
    }
    if (how === 'reset') {
      if (!c.client.destroyed) c.client.resetAndDestroy();
      if (c.upstream && !c.upstream.destroyed) c.upstream.resetAndDestroy();
    } else {
      c.client.destroy();
      c.upstream?.destroy();
    }
  }

  function receiver(c: Conn, dir: Dir): net.Socket | null {
    return dir === 'up' ? c.upstream : c.client;
  }

  /** Deliver what is due, in order; nothing while silent. */
  function pump(c: Conn, dir: Dir): void {
    const p = dir === 'up' ? c.up : c.down;
    if (p.timer) clearTimeout(p.timer);
    p.timer = null;
    if (c.closed || silent()) return;
    const to = receiver(c, dir);
    if (!to || to.connecting) return; // pumped again on connect
    const now = Date.now();
    while (p.queue.length > 0) {
      const head = p.queue[0];
      if (!head) break;
      if (head.due > now) {
        p.timer = setTimeout(() => pump(c, dir), head.due - now);
        return;
      }
      p.queue.shift();
      if (to.destroyed || to.writableEnded) continue;
      to.write(head.chunk);
      if (dir === 'up') stats.bytesUp += head.chunk.length;
      else stats.bytesDown += head.chunk.length;
    }
    if (p.ended && !to.destroyed && !to.writableEnded) to.end();
  }

  function accept(chunk: Buffer, c: Conn, dir: Dir): void {
    if (c.closed) return;
    const p = dir === 'up' ? c.up : c.down;
    let data = chunk;
    if (dir === 'up') {
      // A request (or a frame) from the client: what follows from the target is a new answer.
      c.answerBytes = 0;
    } else if (mode.kind === 'truncate') {
      if (c.cut) return;
      const left = Math.max(0, mode.bytes - c.answerBytes);
      data = chunk.subarray(0, left);
      c.answerBytes += data.length;
      if (data.length < chunk.length) {
        stats.truncated++;
        if (data.length > 0) p.queue.push({ chunk: Buffer.from(data), due: Date.now() });
        pump(c, dir);
        c.cut = true;
        if (mode.then === 'close') {
          // The answer breaks off: what was let through is written, then the connection goes.
          c.upstream?.destroy();
          if (!c.client.destroyed) c.client.end(() => destroy(c, 'close'));
          setTimeout(() => destroy(c, 'close'), 200).unref();
        }
        return;
      }
    }
    const delay = mode.kind === 'latency' ? mode.ms : 0;
    p.queue.push({ chunk: Buffer.from(data), due: Date.now() + delay });
    pump(c, dir);
  }

  function connectUpstream(c: Conn): void {
    const up = net.connect({ host: targetHost, port: o.targetPort });
    c.upstream = up;
    up.setNoDelay(true);
    up.on('connect', () => pump(c, 'up'));
    up.on('data', (d: Buffer) => accept(d, c, 'down'));
    up.on('end', () => {
      c.down.ended = true;
      pump(c, 'down');
    });
    up.on('error', () => undefined);
    up.on('close', () => {
      // The target went away: the client's side follows once what was sent is delivered.
      if (c.closed || c.cut) return;
      if (!silent()) {
        c.down.ended = true;
        pump(c, 'down');
        if (c.down.queue.length === 0) destroy(c, 'close');
      }
    });
  }

  function onConnection(client: net.Socket): void {
    if (mode.kind === 'reset' || closed) {
      stats.resetOnAccept++;
      client.on('error', () => undefined);
      client.resetAndDestroy();
      return;
    }
    stats.connections++;
    client.setNoDelay(true);
    const c: Conn = {
      client,
      upstream: null,
      bornSilent: silent(),
      answerBytes: 0,
      cut: false,
      up: newPipe(),
      down: newPipe(),
      closed: false,
      clientReset: false,
    };
    conns.add(c);
    client.on('data', (d: Buffer) => accept(d, c, 'up'));
    client.on('end', () => {
      c.up.ended = true;
      if (silent() && !c.bornSilent && c.up.queue.length > 0) stats.finWhileHeld++;
      pump(c, 'up');
    });
    client.on('error', (e: NodeJS.ErrnoException) => {
      if (e.code === 'ECONNRESET') c.clientReset = true;
    });
    client.on('close', () => {
      if (c.closed) return;
      if (silent()) {
        const held = queuedBytes(c.up);
        if (c.clientReset || c.bornSilent) {
          if (c.clientReset && held > 0) stats.resetWhileHeld++;
          stats.heldDropped += held;
          destroy(c, 'close');
        }
        // A graceful close of an established connection: what it sent is delivered at the end
        // of the silence (see `heal`), then the target's side is ended.
        return;
      }
      // Deliver what is queued towards the target, then end it.
      c.up.ended = true;
      pump(c, 'up');
      if (c.up.queue.length === 0) destroy(c, 'close');
    });
    if (!c.bornSilent) connectUpstream(c);
  }

  async function listen(): Promise<void> {
    const s = net.createServer(onConnection);
    for (let attempt = 0; ; attempt++) {
      try {
        await new Promise<void>((resolve, reject) => {
          s.once('error', reject);
          s.listen(port, host, () => {
            s.off('error', reject);
            resolve();
          });
        });
        break;
      } catch (e) {
        // The port was ours a moment ago; something may hold it briefly.
        if (attempt >= 20) throw e;
        await new Promise((r) => setTimeout(r, 50));
      }
    }
    server = s;
    port = (s.address() as net.AddressInfo).port;
  }

  async function unlisten(): Promise<void> {
    const s = server;
    server = null;
    if (!s) return;
    await new Promise<void>((resolve) => {
      s.close(() => resolve());
      // Connections are ours to end (`destroy`), not the server's: do not wait for them.
      setTimeout(resolve, 0);
    });
  }

  /** The silence ended: established connections deliver what was held; late-born ones connect. */
  function heal(): void {
    for (const c of [...conns]) {
      stats.heldDelivered += queuedBytes(c.up) + queuedBytes(c.down);
      if (c.bornSilent && !c.upstream) {
        c.bornSilent = false;
        if (c.client.destroyed) {
          stats.heldDropped += queuedBytes(c.up);
          destroy(c, 'close');
          continue;
        }
        connectUpstream(c);
      }
      pump(c, 'up');
      pump(c, 'down');
      if (c.client.destroyed && c.up.queue.length === 0) {
        // Its client closed gracefully during the silence: end the target's side too.
        c.upstream?.end();
        setTimeout(() => destroy(c, 'close'), 200).unref();
      }
    }
  }

  function resetAll(): void {
    for (const c of [...conns]) destroy(c, 'reset');
  }

  await listen();

  async function set(next: FaultMode): Promise<void> {
    if (closed) return;
    const gen = ++generation;
    const was = mode;
    mode = next;
    if (restartTimer) clearTimeout(restartTimer);
    restartTimer = null;
    switch (next.kind) {
      case 'pass':
      case 'latency':
      case 'truncate':
        if (!server) await listen();
        // A connection cut in the middle of an answer cannot carry on: it goes.
        if (next.kind !== 'truncate') for (const c of [...conns]) if (c.cut) destroy(c, 'close');
        break;
      case 'silent':
        if (!server) await listen();
        break;
      case 'reset':
        if (!server) await listen();
        resetAll();
        break;
      case 'refuse':
        resetAll();
        await unlisten();
        break;
      case 'restart':
        resetAll();
        await unlisten();
        restartTimer = setTimeout(() => {
          if (gen !== generation || closed) return;
          void set({ kind: 'pass' });
        }, next.downMs);
        break;
    }
    if (was.kind === 'silent' && next.kind !== 'silent') heal();
  }

  return {
    host,
    get port() {
      return port;
    },
    url: (scheme = 'http') => `${scheme}://${host}:${port}`,
    get mode() {
      return mode;
    },
    set,
    stats: () => ({ ...stats, open: conns.size }),
    resetStats() {
      stats = zeroStats();
    },
    async close() {
      closed = true;
      generation++;
      if (restartTimer) clearTimeout(restartTimer);
      for (const c of [...conns]) destroy(c, 'close');
      await unlisten();
    },
  };
}
