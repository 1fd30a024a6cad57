import { EventEmitter } from 'node:events';
import { WebSocket, type RawData } from 'ws';
import type { Simulator } from '../src/fleet/sim';

/** The controller's side of a shared socket (a real WebSocket or a simulator's). */
export interface UpstreamSocket {
  send(text: string): void;
  close(code: number, reason: string): void;
  onMessage(cb: (data: Buffer, isBinary: boolean) => void): void;
  onClose(cb: (code: number, reason: string) => void): void;
  /** Pause/resume reading (real sockets): a flood waits in TCP buffers, not here. */
  pause?(): void;
  resume?(): void;
}

function toBuffer(data: RawData): Buffer {
  if (Buffer.isBuffer(data)) return data;
  if (Array.isArray(data)) return Buffer.concat(data);
  return Buffer.from(data);
}

/** A controller's real WebSocket as a hub's upstream; `early` frames came before the hub. */
export function wsUpstream(
  ws: WebSocket,
  early: Array<{ data: RawData; isBinary: boolean }> = [],
): UpstreamSocket {
  ws.on('error', () => ws.terminate());
  return {
    send: (t) => {
      if (ws.readyState === WebSocket.OPEN) ws.send(t);
    },
    close: (code, reason) => {
      if (ws.readyState === WebSocket.OPEN || ws.readyState === WebSocket.CONNECTING) ws.close(code, reason);
    },
    onMessage: (cb) => {
      for (const e of early.splice(0)) cb(toBuffer(e.data), e.isBinary);
      ws.on('message', (data: RawData, isBinary: boolean) => cb(toBuffer(data), isBinary));
    },
    onClose: (cb) => {
      if (ws.readyState === WebSocket.CLOSED) cb(1006, '');
      else ws.once('close', (code: number, reason: Buffer) => cb(code, reason.toString('utf8')));
    },
    pause: () => ws.pause(),
    resume: () => ws.resume(),
  };
}

/**
 * A simulator's socket as a hub's upstream (simulated machines stand in for hardware). Frames
 * the simulator sends before the hub listens (its greeting) wait for it. `events` emits
 * 'close' (the held session tracks it).
 */
export function simUpstream(
  sim: Simulator,
  path: string,
): { socket: UpstreamSocket; events: EventEmitter } | null {
  const events = new EventEmitter();
  const waiting: Buffer[] = [];
  let listener: ((data: Buffer, isBinary: boolean) => void) | null = null;
  let closed = false;
  const ended = (code: number, reason: string): void => {
    if (closed) return;
    closed = true;
    events.emit('close', code, reason);
  };
  const h = sim.socket?.(path, {
    send: (d) => {
      if (closed) return;
      const b = Buffer.from(d, 'utf8');
      if (listener) listener(b, false);
      else waiting.push(b);
    },
    close: (code, reason) => queueMicrotask(() => ended(code ?? 1000, reason ?? '')),
  });
  if (!h) return null;
  return {
    events,
    socket: {
      send: (t) => {
        if (!closed) h.message(t);
      },
      close: (code, reason) => {
        if (closed) return;
        h.close();
        ended(code, reason);
      },
      onMessage: (cb) => {
        listener = cb;
        for (const b of waiting.splice(0)) cb(b, false);
      },
      onClose: (cb) => {
        if (closed) cb(1006, '');
        else events.once('close', cb);
      },
    },
  };
}
