import type { FrameClass } from '../src/fleet/contract';
import type { HubStats, StreamLimits } from './stream-options';
import type { UpstreamSocket } from './stream-upstream';

/** A controller frame waiting for its turn, with its class (fan-out) computed once. */
export interface Inbound {
  raw: Buffer;
  isBinary: boolean;
  cls: FrameClass | null;
}

/**
 * A shared stream's controller frames on their way in (streams.ts `StreamHub`): queued, coalesced
 * (a `latest` frame replaces the waiting one of its key when no event came between), handled in
 * turns of the event loop, the controller paused past its rate, and a flood reported.
 */
export class UpstreamInbox {
  private windowStart: number;
  private windowCount = 0;
  /** Frames of this window that cannot be coalesced, and windows in a row that had too many. */
  private windowEvents = 0;
  private floodWindows = 0;
  private pausedUntil: ReturnType<typeof setTimeout> | null = null;
  /**
   * Frames not handled yet (from `head` on): a burst waits here between turns. `waitingLatest`:
   * key → index of the waiting `latest` frame of that key, so a burst of state waits as one per key.
   */
  private inbox: Array<Inbound | undefined> = [];
  private head = 0;
  private readonly waitingLatest = new Map<string, number>();
  /** Frames in the inbox that cannot be coalesced, and the inbox's bytes. */
  private queuedFrames = 0;
  private queuedBytes = 0;
  /** What this turn of the event loop handled so far; reset by `turnTimer`. */
  private turnFrames = 0;
  private turnBytes = 0;
  private turnTimer: ReturnType<typeof setImmediate> | null = null;
  private stopped = false;

  constructor(
    private readonly limits: StreamLimits,
    private readonly now: () => number,
    private readonly upstream: UpstreamSocket,
    private readonly stats: Pick<HubStats, 'coalesced' | 'deferred'>,
    private readonly hooks: {
      /** One frame's turn came (redaction, the watch, the browsers). */
      handle: (f: Inbound) => void;
      /** The controller floods faster than its frames can be handled. */
      flooded: () => void;
    },
  ) {
    this.windowStart = now();
  }

  /**
   * A controller frame: queued, coalesced with a waiting one of its key when the family says it
   * supersedes it, and handled in turns of at most `batchFrames`/`batchBytes`; the event loop runs
   * between turns. ws hands over every frame of a read at once, whatever `pause()`: a burst of
   * 20,000 costs here only its classification.
   */
  take(raw: Buffer, isBinary: boolean, cls: FrameClass | null): void {
    if (cls?.kind !== 'latest' && ++this.windowEvents === this.limits.maxFramesPerSecond) {
      if (++this.floodWindows >= this.limits.floodSeconds) return this.hooks.flooded();
    }
    if (cls?.kind === 'latest') {
      const i = this.waitingLatest.get(cls.key);
      const waiting = i === undefined ? undefined : this.inbox[i];
      if (i !== undefined && waiting && i >= this.head) {
        this.stats.coalesced++;
        this.queuedBytes += raw.length - waiting.raw.length;
        this.inbox[i] = { raw, isBinary, cls };
      } else {
        this.waitingLatest.set(cls.key, this.inbox.length);
        this.queuedBytes += raw.length;
        this.inbox.push({ raw, isBinary, cls });
      }
    } else {
      // An event (or a model patch) keeps its place: state before it is not replaced by state after.
      this.waitingLatest.clear();
      this.queuedFrames++;
      this.queuedBytes += raw.length;
      this.inbox.push({ raw, isBinary, cls });
    }
    if (this.queuedFrames > this.limits.maxQueuedFrames || this.queuedBytes > this.limits.maxQueuedBytes)
      return this.hooks.flooded();
    this.drain();
  }

  /** Handles waiting frames up to this turn's budget; the rest in the next turn. */
  private drain(): void {
    while (this.head < this.inbox.length && !this.stopped) {
      if (this.turnFrames >= this.limits.batchFrames || this.turnBytes >= this.limits.batchBytes) {
        if (!this.turnTimer) this.stats.deferred++;
        break;
      }
      const f = this.inbox[this.head];
      this.inbox[this.head++] = undefined; // handled: its buffer may go
      if (!f) continue;
      if (f.cls?.kind !== 'latest') this.queuedFrames--;
      this.queuedBytes -= f.raw.length;
      this.turnFrames++;
      this.turnBytes += f.raw.length;
      this.hooks.handle(f);
    }
    if (this.head >= this.inbox.length) {
      this.inbox = [];
      this.head = 0;
      this.waitingLatest.clear();
    }
    if ((this.turnFrames || this.head < this.inbox.length) && !this.turnTimer && !this.stopped) {
      this.turnTimer = setImmediate(() => {
        this.turnTimer = null;
        this.turnFrames = 0;
        this.turnBytes = 0;
        this.drain();
      });
    }
  }

  /** A flooding controller is paused for the rest of the second (its frames wait in TCP). */
  rateBound(): void {
    const t = this.now();
    if (t - this.windowStart >= 1000) {
      // A window without too many events ends the run of flooded ones.
      if (this.windowEvents < this.limits.maxFramesPerSecond || t - this.windowStart >= 2000)
        this.floodWindows = 0;
      this.windowStart = t;
      this.windowCount = 0;
      this.windowEvents = 0;
    }
    if (++this.windowCount < this.limits.maxFramesPerSecond || !this.upstream.pause || this.pausedUntil)
      return;
    this.upstream.pause();
    this.pausedUntil = setTimeout(
      () => {
        this.pausedUntil = null;
        this.upstream.resume?.();
      },
      Math.max(1, 1000 - (t - this.windowStart)),
    );
  }

  /** The hub ended: nothing more is handled, no timer left. */
  stop(): void {
    this.stopped = true;
    if (this.pausedUntil) clearTimeout(this.pausedUntil);
    if (this.turnTimer) clearImmediate(this.turnTimer);
    this.turnTimer = null;
    this.inbox = [];
    this.head = 0;
    this.waitingLatest.clear();
  }
}
