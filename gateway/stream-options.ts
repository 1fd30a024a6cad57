/**
 * A shared stream's (streams.ts) options, bounds (slow browsers, floods, turns of the event loop)
 * and counters.
 */

export interface StreamLimits {
  /** A browser's send buffer above this: `latest` frames wait (newest wins). */
  highWaterBytes: number;
  /** Above this, a browser is too slow even for events: closed with 1013. */
  hardLimitBytes: number;
  /** Upstream frames a second before the controller's socket is paused for the rest of it. */
  maxFramesPerSecond: number;
  /** Frames a browser may send a second before it is closed (1008). */
  maxBrowserFramesPerSecond: number;
  /** `replay` events kept for browsers that join later. */
  replayEvents: number;
  /** Model events (Duet messages) kept per browser between two acknowledgements. */
  pendingEvents: number;
  /**
   * Controller frames handled (redacted, read, given to browsers) in one turn of the event loop;
   * the rest wait for the next turn, so one machine's burst never holds up the others.
   */
  batchFrames: number;
  /** Bytes of controller frames handled in one turn (redaction costs by the byte). */
  batchBytes: number;
  /**
   * Frames waiting for a turn that cannot be coalesced (events, model patches): past this, or past
   * `maxQueuedBytes`, the controller floods faster than it can be handled and its socket is closed.
   */
  maxQueuedFrames: number;
  maxQueuedBytes: number;
  /**
   * Seconds in a row with `maxFramesPerSecond` frames or more that cannot be coalesced (events,
   * patches) before the controller's socket is closed as flooding (state frames are coalesced).
   */
  floodSeconds: number;
}

export const DEFAULT_STREAM_LIMITS: StreamLimits = {
  highWaterBytes: 256 * 1024,
  hardLimitBytes: 4 * 1024 * 1024,
  maxFramesPerSecond: 200,
  maxBrowserFramesPerSecond: 60,
  replayEvents: 20,
  pendingEvents: 500,
  batchFrames: 64,
  batchBytes: 1024 * 1024,
  maxQueuedFrames: 2000,
  maxQueuedBytes: 16 * 1024 * 1024,
  floodSeconds: 5,
};

/**
 * A model stream's upstream is dead after this many keep-alive periods without any frame (Duet:
 * 2 s → PING, dead at 4.5 s): within the 5 s for a silent link, and above the 4 s round
 * trip of a slow (2 s each way) link whose patches still come.
 */
export const UPSTREAM_DEAD_AFTER_PINGS = 2.25;
/** How often the keep-alive rule is checked (at most). */
export const UPSTREAM_CHECK_MS = 100;

export interface HubOptions {
  /** Every controller frame passes here first (redaction). */
  toClient?: (data: Buffer, isBinary: boolean) => Buffer;
  limits?: Partial<StreamLimits>;
  now?: () => number;
  /** Called once when the hub ended (upstream closed or grace over): forget it. */
  onEnd?: () => void;
  /** Problems worth a log line (a model frame that does not parse). */
  warn?: (msg: string) => void;
}

export interface HubStats {
  viewers: number;
  framesIn: number;
  framesOut: number;
  /** `latest` frames replaced by a newer one before a browser got them. */
  coalesced: number;
  /** Browsers closed for being too slow. */
  slowClosed: number;
  /** Turns a burst of controller frames was spread over (the event loop ran between them). */
  deferred: number;
}
