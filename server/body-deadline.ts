import type { IncomingMessage, ServerResponse } from 'node:http';
import { isStreamedBody } from '../gateway/http-util';

export interface BodyDeadline {
  /** A body the gateway reads itself must have arrived whole by then (ms from the headers). */
  totalMs: number;
  /** A body streamed on to a controller (markStreamedBody) may take longer, never stall this long. */
  stallMs: number;
}

function hasBody(req: IncomingMessage): boolean {
  const cl = req.headers['content-length'];
  return (cl !== undefined && cl.trim() !== '0') || req.headers['transfer-encoding'] !== undefined;
}

/**
 * The slow-loris bound of one request's body, in place of Node's `server.requestTimeout` (which
 * would cut an upload that takes long to send: 408 and a reset). Headers are bounded by
 * `server.headersTimeout`; a body by this: whole within `totalMs`, unless the gateway streams it
 * on (an upload to a controller or a simulator) and has not answered yet; such a body is cut
 * when no byte of it came for `stallMs`. A cut request is answered 408 (when nothing was
 * answered yet) and its connection closed.
 */
export function guardBody(req: IncomingMessage, res: ServerResponse, limits: BodyDeadline): void {
  if (!hasBody(req)) return;
  const socket = req.socket;
  let timer: NodeJS.Timeout | null = null;
  let lastRead = -1;
  const stop = (): void => {
    if (timer) clearTimeout(timer);
    timer = null;
    req.off('end', stop);
    socket.off('close', stop);
  };
  const arm = (ms: number): void => {
    timer = setTimeout(check, ms);
    timer.unref();
  };
  const check = (): void => {
    timer = null;
    if (req.complete || socket.destroyed) return stop();
    if (isStreamedBody(req) && !res.writableEnded && socket.bytesRead !== lastRead) {
      lastRead = socket.bytesRead;
      return arm(limits.stallMs);
    }
    stop();
    if (res.headersSent) {
      socket.destroy();
      return;
    }
    const text = 'the request body did not arrive in time: nothing was done with it\n';
    res.writeHead(408, {
      'Content-Type': 'text/plain; charset=utf-8',
      'Content-Length': Buffer.byteLength(text),
      'Cache-Control': 'no-store',
      Connection: 'close',
    });
    res.end(text, () => socket.destroy());
  };
  req.once('end', stop);
  socket.once('close', stop);
  arm(limits.totalMs);
}
