import type { SessionContext } from '../../fleet/contract';
import { LinkError } from '../../fleet/errors';
import { gridDelay, type SocketLink } from '../../fleet/link';
import { POLL_AFTER_MS, POLL_SILENT_MS, RESYNC_EVERY_MS, TILE_ACK_MS } from './timing';

/** The Duet socket's rules beside the session: what a close means, the `OK` pacing, resync, the socket down. */

/**
 * What a closed socket means: 1008/4403 a refused upgrade (the session is gone: `refused`), 1007
 * the console server refused a frame of the Duet's (bad data), 1001/1011 DSF (or the link to it)
 * down, anything else a network problem. Never a verdict on the Duet.
 */
export function socketCloseError(
  code: number,
  reason: string,
  hadModel: boolean,
): { refused: boolean; error: LinkError } {
  if (code === 1008 || code === 4403)
    return {
      refused: true,
      error: new LinkError('http', `socket refused (${reason || code})`, { status: 403 }),
    };
  const why = reason ? `: ${reason}` : '';
  if (code === 1007)
    return {
      refused: false,
      error: new LinkError('protocol', `WS /machine: the Duet sent data the console cannot use${why}`, {
        path: '(root)',
      }),
    };
  if (code === 1001 || code === 1011)
    return {
      refused: false,
      error: new LinkError(
        'network',
        `The Duet service (DSF) or the link to it is down: socket closed with ${code}${reason ? ` (${reason})` : ''}`,
      ),
    };
  return {
    refused: false,
    error: new LinkError(
      'network',
      `Socket closed (${code}${why})${hadModel ? '' : ' before the object model arrived'}`,
    ),
  };
}

/** The heartbeat found the socket dead: no answer to PING, or no model after connecting. */
export function socketDeadError(why: string, hadModel: boolean): LinkError {
  return new LinkError(
    'timeout',
    hadModel ? `${why}: the link is dead` : `The object model did not arrive (${why.toLowerCase()})`,
  );
}

/** No polled model for POLL_SILENT_MS while it is the source of data: the link is down. */
export function pollSilentError(quietMs: number, standalone: boolean): LinkError {
  return new LinkError(
    'timeout',
    `No answer from the Duet for ${Math.round(quietMs / 1000)} s (${
      standalone ? 'GET /rr_model' : 'GET /machine/model; the live socket is down'
    })`,
  );
}

/**
 * Since when the socket does not deliver (`since`, null: it does, or it was never opened), and
 * whether the model polled meanwhile keeps coming (the machine then stays online, only slower).
 */
export class SocketDown {
  since: number | null = null;
  private lastPollOkAt = 0;

  constructor(private readonly now: () => number) {}

  /** The socket failed: true when it just went down. */
  failed(): boolean {
    if (this.since !== null) return false;
    this.since = this.now();
    return true;
  }

  /** The socket delivers again (or the run stopped). */
  back(): void {
    this.since = null;
    this.lastPollOkAt = 0;
  }

  polledOk(): void {
    this.lastPollOkAt = this.now();
  }

  pollingHealthy(): boolean {
    return this.lastPollOkAt > 0 && this.now() - this.lastPollOkAt < POLL_SILENT_MS;
  }

  /** Down for POLL_AFTER_MS: the model is polled (a quick reconnect needs none). */
  pollTime(): boolean {
    return this.since !== null && this.now() - this.since >= POLL_AFTER_MS;
  }
}

/** A timeout of the session's current run (KernelSession.later). */
type Later = (fn: () => void, ms: number) => void;

/**
 * The `OK` after a frame: at once on the machine's page, at the tile's pace (TILE_ACK_MS, on the
 * grid of the tiles' polls) otherwise. One `OK` per frame: the sender waits for it, so at most one
 * is ever waiting per socket, and only the socket that sent the frame gets it.
 */
export class AckPacer {
  /** When the last `OK` went, and whether one waits to go. */
  private lastAckAt = 0;
  private waiting: { generation: number } | null = null;

  constructor(
    private readonly ctx: Pick<SessionContext, 'now' | 'detail'>,
    private readonly socket: () => SocketLink | null,
    private readonly later: Later,
  ) {}

  acknowledge(): void {
    const socket = this.socket();
    if (!socket) return;
    if (this.waiting?.generation === socket.generation) return;
    const now = this.ctx.now();
    // On the grid of the tiles' polls (gridDelay), the next grid moment after the last `OK`.
    const wait = this.ctx.detail()
      ? 0
      : gridDelay(Math.max(now, this.lastAckAt), TILE_ACK_MS) + Math.max(0, this.lastAckAt - now);
    if (wait <= 0) {
      this.waiting = null;
      this.lastAckAt = now;
      socket.send('OK\n');
      return;
    }
    const mine = { generation: socket.generation };
    this.waiting = mine;
    this.later(() => {
      if (this.waiting !== mine) return;
      this.waiting = null;
      // Only on the socket that sent the frame: a new socket starts with a full model of its own.
      if (this.socket() !== socket || socket.generation !== mine.generation) return;
      this.lastAckAt = this.ctx.now();
      socket.send('OK\n');
    }, wait);
  }
}

/**
 * After a dropped frame (bad data: shown, logged) the model may differ from the machine's: a new
 * socket reads it whole (DSF sends the full model first), now or once RESYNC_EVERY_MS has passed
 * since the last time; the session and its link stay as they are.
 */
export class Resync {
  private lastAt = -Infinity;
  private due = false;

  constructor(
    private readonly o: {
      now: () => number;
      later: Later;
      started: () => boolean;
      /** Opens the new socket if the link allows it now (true: it did). */
      reconnect: () => void;
    },
  ) {}

  request(): void {
    if (this.due || !this.o.started()) return;
    this.due = true;
    const wait = Math.max(0, this.lastAt + RESYNC_EVERY_MS - this.o.now());
    this.o.later(() => {
      if (!this.due) return;
      this.due = false;
      this.lastAt = this.o.now();
      this.o.reconnect();
    }, wait);
  }

  /** The run stopped: a resync waiting its turn is dropped. */
  reset(): void {
    this.due = false;
  }
}
