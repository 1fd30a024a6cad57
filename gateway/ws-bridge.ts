import { WebSocket, type RawData } from 'ws';

/**
 * The bridge between a browser's socket and a controller's socket, with bounds. A controller may
 * be hostile or broken (floods, huge frames) and a browser may be slow (a tablet on weak Wi-Fi):
 * neither may make the gateway buffer without limit, and a flood must not freeze the page.
 *
 * - Frame size: both sockets are opened with a `maxPayload` (ws closes with 1009 above it).
 * - Browser slow: when the browser's send buffer holds more than `highWaterBytes`, the controller
 *   socket is paused (TCP pushes back) until it drains. Frames are never dropped or reordered,
 *   because a family may depend on every one (Duet's model patches).
 * - Flood: at most `maxFramesPerSecond` frames a second reach the browser; past that the
 *   controller socket is paused until the next second. Frames wait in the controller's TCP
 *   buffers, not in the gateway's memory.
 * - Browser → controller: the same frame rate bound (a page has no reason to send more).
 */

export interface BridgeLimits {
  /** Largest frame from the controller, bytes. */
  maxUpstreamFrame: number;
  /** Largest frame from the browser, bytes. */
  maxClientFrame: number;
  /** Pause the controller socket while the browser's send buffer holds more than this. */
  highWaterBytes: number;
  maxFramesPerSecond: number;
}

export const DEFAULT_BRIDGE_LIMITS: BridgeLimits = {
  maxUpstreamFrame: 8 * 1024 * 1024,
  maxClientFrame: 1024 * 1024,
  highWaterBytes: 1024 * 1024,
  maxFramesPerSecond: 60,
};

export interface BridgeOptions {
  limits?: Partial<BridgeLimits>;
  /** Every frame from the controller passes here before the browser sees it (redaction). */
  toClient?: (data: Buffer, isBinary: boolean) => Buffer;
  /** Called once when either side has closed. */
  onClose?: () => void;
  now?: () => number;
}

/** The ws close code to pass on, or undefined when the code may not be sent by an endpoint. */
function passableCode(code: number): number | undefined {
  return (code >= 1000 && code <= 1003) || (code >= 1007 && code <= 1014) || (code >= 3000 && code <= 4999)
    ? code
    : undefined;
}

function toBuffer(data: RawData): Buffer {
  if (Buffer.isBuffer(data)) return data;
  if (Array.isArray(data)) return Buffer.concat(data);
  return Buffer.from(data);
}

export interface Bridge {
  /** Frames held back so far because the browser was slow or the controller flooded. */
  readonly stats: { paused: number; framesToClient: number; framesToUpstream: number };
  close(code: number, reason: string): void;
}

export function bridgeSockets(client: WebSocket, upstream: WebSocket, opts: BridgeOptions = {}): Bridge {
  const limits = { ...DEFAULT_BRIDGE_LIMITS, ...opts.limits };
  const now = opts.now ?? Date.now;
  const stats = { paused: 0, framesToClient: 0, framesToUpstream: 0 };
  let closed = false;
  let pausedFor: 'none' | 'drain' | 'rate' = 'none';
  let windowStart = now();
  let windowCount = 0;
  let clientWindowStart = now();
  let clientWindowCount = 0;
  let rateTimer: ReturnType<typeof setTimeout> | null = null;

  const finish = (): void => {
    if (closed) return;
    closed = true;
    if (rateTimer) clearTimeout(rateTimer);
    opts.onClose?.();
  };

  const pauseUpstream = (why: 'drain' | 'rate'): void => {
    if (pausedFor !== 'none') return;
    pausedFor = why;
    stats.paused++;
    if (upstream.isPaused) return;
    upstream.pause();
  };
  // ws may still emit frames it had already read when paused: they wait here (at most one read
  // buffer's worth), in order, and go first when the bridge resumes.
  const held: Array<{ data: RawData; isBinary: boolean }> = [];
  const resumeUpstream = (): void => {
    if (pausedFor === 'none' || closed) return;
    pausedFor = 'none';
    while (held.length && pausedFor === 'none') {
      const f = held.shift();
      if (f) deliver(f.data, f.isBinary);
    }
    if (pausedFor === 'none') upstream.resume();
  };

  upstream.on('message', (data: RawData, isBinary: boolean) => {
    if (pausedFor !== 'none') held.push({ data, isBinary });
    else deliver(data, isBinary);
  });

  function deliver(data: RawData, isBinary: boolean): void {
    if (client.readyState !== WebSocket.OPEN) return;
    const t = now();
    if (t - windowStart >= 1000) {
      windowStart = t;
      windowCount = 0;
    }
    windowCount++;
    let buf = toBuffer(data);
    if (opts.toClient) buf = opts.toClient(buf, isBinary);
    stats.framesToClient++;
    client.send(buf, { binary: isBinary }, () => {
      if (pausedFor === 'drain' && client.bufferedAmount <= limits.highWaterBytes / 2) resumeUpstream();
    });
    if (client.bufferedAmount > limits.highWaterBytes) {
      pauseUpstream('drain');
    } else if (windowCount >= limits.maxFramesPerSecond) {
      pauseUpstream('rate');
      rateTimer = setTimeout(
        () => {
          rateTimer = null;
          if (pausedFor === 'rate') {
            if (client.bufferedAmount > limits.highWaterBytes) pausedFor = 'drain';
            else resumeUpstream();
          }
        },
        Math.max(1, 1000 - (now() - windowStart)),
      );
    }
  }

  client.on('message', (data: RawData, isBinary: boolean) => {
    const t = now();
    if (t - clientWindowStart >= 1000) {
      clientWindowStart = t;
      clientWindowCount = 0;
    }
    if (++clientWindowCount > limits.maxFramesPerSecond) {
      client.close(1008, 'too many frames');
      return;
    }
    if (upstream.readyState === WebSocket.OPEN) {
      stats.framesToUpstream++;
      upstream.send(toBuffer(data), { binary: isBinary });
    }
  });

  const pass = (from: WebSocket, to: WebSocket): void => {
    from.on('close', (code: number, reason: Buffer) => {
      finish();
      if (to.readyState === WebSocket.OPEN || to.readyState === WebSocket.CONNECTING) {
        const c = passableCode(code);
        if (code === 1006) to.terminate();
        else if (c === undefined) to.close();
        else to.close(c, reason.toString('utf8').slice(0, 120));
      }
    });
    from.on('error', () => {
      finish();
      to.terminate();
    });
  };
  pass(client, upstream);
  pass(upstream, client);

  return {
    stats,
    close(code, reason) {
      if (client.readyState === WebSocket.OPEN || client.readyState === WebSocket.CONNECTING)
        client.close(code, reason.slice(0, 120));
      if (upstream.readyState === WebSocket.OPEN || upstream.readyState === WebSocket.CONNECTING)
        upstream.close(1000, 'the console closed the socket');
      finish();
    },
  };
}
