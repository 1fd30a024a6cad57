import { EventEmitter } from 'node:events';
import { WebSocket, type RawData } from 'ws';
import type { Simulator } from '../src/fleet/sim';
import type {
  FrameClass,
  JsonRecord,
  JsonValue,
  ModelStreamDecl,
  SharedStreamDecl,
} from '../src/fleet/contract';

/**
 * Shared controller sockets: one upstream socket per machine and stream, whatever the number of
 * viewers (the family declares which sockets, `SharingHints.streams` in src/fleet/contract.ts).
 *
 * - **Fan-out** (xTool :8081, Prunt `/websocket/everything`): every controller frame is redacted
 *   once and given to every browser socket of the machine. A `latest` frame (state) waits while
 *   a browser is slow or throttled and only the newest of its key is delivered; a browser joining
 *   later is first given the newest `replay` ones. An `event` frame (log line, alarm) is delivered
 *   in order, never dropped: a browser whose send buffer passes the hard bound is closed (1013)
 *   and reconnects rather than being buffered without end. Browser frames never reach the
 *   controller as they are: a rate wish (Prunt's divisor) is kept per browser and the fastest one
 *   wanted goes upstream; the rest is answered here or dropped.
 * - **Model** (Duet DSF `WS /machine`): the gateway keeps the merged model, acknowledges each
 *   patch upstream at once, and gives every browser the full model first, then, each time that
 *   browser acknowledges, one patch from what it has to what is now (the controller's own patch
 *   when the browser is up to date). Its keep-alive (`PING`) is answered here; the gateway pings
 *   upstream itself, and an upstream silent for 2.25 keep-alive periods is gone: every browser
 *   socket is closed (1011), so the pages show the link down within the 5 s. A frame
 *   the model cannot take (not a model, a patch that does not apply) closes them with 1007: bad
 *   data, which the pages show as such, and everyone starts again from a fresh full model.
 * - The upstream socket opens with the first viewer and closes `graceMs` after the last one left,
 *   unless something holds it (`hold()`: the gateway's watch). When the controller closes it,
 *   every browser socket of the hub is closed (1011) and reconnects to a fresh hub.
 * - A slow browser never slows the others or the controller: nothing waits on a browser.
 */

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

interface Viewer {
  ws: WebSocket;
  /** Fan-out: newest undelivered `latest` frame per key. */
  pending: Map<string, { data: Buffer; isBinary: boolean }>;
  /** The rate this browser asked for (null: none, the family's default applies). */
  rateMs: number | null;
  lastLatestAt: number;
  timer: ReturnType<typeof setTimeout> | null;
  /** Model: the model as this browser has it, and whether it asked for the next patch. */
  sent: JsonRecord | null;
  wantsNext: boolean;
  events: JsonValue[];
  windowStart: number;
  windowCount: number;
}

const CLOSED_BY_CONTROLLER = 1011;
/** A model stream's controller sent a frame the model cannot take (1007: invalid payload data). */
const BAD_DATA_FROM_CONTROLLER = 1007;

/**
 * A model stream's upstream is dead after this many keep-alive periods without any frame (Duet:
 * 2 s → PING, dead at 4.5 s): within the 5 s for a silent link, and above the 4 s round
 * trip of a slow (2 s each way) link whose patches still come.
 */
export const UPSTREAM_DEAD_AFTER_PINGS = 2.25;
/** How often the keep-alive rule is checked (at most). */
export const UPSTREAM_CHECK_MS = 100;

function text(data: Buffer): string {
  return data.toString('utf8');
}

/** A controller frame waiting for its turn, with its class (fan-out) computed once. */
interface Inbound {
  raw: Buffer;
  isBinary: boolean;
  cls: FrameClass | null;
}

export class StreamHub {
  readonly stats: HubStats = {
    viewers: 0,
    framesIn: 0,
    framesOut: 0,
    coalesced: 0,
    slowClosed: 0,
    deferred: 0,
  };
  private readonly viewers = new Set<Viewer>();
  private readonly limits: StreamLimits;
  private readonly now: () => number;
  private ended = false;
  private holds = 0;
  private graceTimer: ReturnType<typeof setTimeout> | null = null;
  private pingTimer: ReturnType<typeof setInterval> | null = null;
  private lastHeard: number;
  private lastPingAt = 0;
  private windowStart: number;
  private windowCount = 0;
  /** Frames of this window that cannot be coalesced, and windows in a row that had too many. */
  private windowEvents = 0;
  private floodWindows = 0;
  private pausedUntil: ReturnType<typeof setTimeout> | null = null;
  /** Fan-out: newest `latest` frames with `replay`, and the last `replay` events. */
  private readonly replayLatest = new Map<string, { data: Buffer; isBinary: boolean }>();
  private readonly replayEvents: Array<{ data: Buffer; isBinary: boolean }> = [];
  private upstreamRateMs: number | null = null;
  /**
   * Frames that came after the controller's socket opened and before the first viewer joined
   * (the viewer who opened it must not miss them); null once someone joined.
   */
  private beforeFirstViewer: Array<{ data: Buffer; isBinary: boolean }> | null = [];
  /** Model: the merged model (null until the full model came), the frame that made it. */
  private model: JsonRecord | null = null;
  private readonly frameListeners = new Set<(frame: string) => void>();
  private readonly endListeners = new Set<() => void>();
  /**
   * Controller frames not handled yet (from `head` on): a burst waits here between turns. A fan-out
   * `latest` frame replaces the waiting one of its key when no event came between (`waitingLatest`:
   * key → index), so a burst of state frames waits as one frame per key.
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

  constructor(
    readonly decl: SharedStreamDecl,
    private readonly upstream: UpstreamSocket,
    private readonly opts: HubOptions = {},
  ) {
    this.limits = { ...DEFAULT_STREAM_LIMITS, ...opts.limits };
    this.now = opts.now ?? Date.now;
    this.lastHeard = this.now();
    this.windowStart = this.now();
    upstream.onMessage((data, isBinary) => this.fromUpstream(data, isBinary));
    upstream.onClose((code, reason) => this.end(CLOSED_BY_CONTROLLER, this.closeWords(code, reason)));
    if (decl.kind === 'model' && decl.ping) {
      const { frame, everyMs } = decl.ping;
      const deadMs = Math.round(everyMs * UPSTREAM_DEAD_AFTER_PINGS);
      this.pingTimer = setInterval(
        () => this.checkUpstream(frame, everyMs, deadMs),
        Math.max(10, Math.min(UPSTREAM_CHECK_MS, Math.round(everyMs / 8))),
      );
    }
    this.scheduleGrace();
  }

  get open(): boolean {
    return !this.ended;
  }

  /**
   * The upstream keep-alive: `frame` after `everyMs` of silence (again every `everyMs`), and the
   * controller is gone when nothing at all came for `deadMs`. Checked often, so a silent upstream
   * is noticed within `deadMs` + a check (the viewers' sockets close, 1011).
   */
  private checkUpstream(frame: string, everyMs: number, deadMs: number): void {
    if (this.ended) return;
    const t = this.now();
    const quiet = t - this.lastHeard;
    if (quiet >= deadMs) {
      this.upstream.close(1001, 'no answer to the keep-alive');
      this.end(CLOSED_BY_CONTROLLER, 'the controller stopped answering');
    } else if (quiet >= everyMs && t - this.lastPingAt >= everyMs) {
      this.lastPingAt = t;
      this.upstream.send(frame);
    }
  }

  /** A model stream's merged model now (null until the full model came, and for fan-out streams). */
  get merged(): JsonRecord | null {
    return this.ended ? null : this.model;
  }

  get viewerCount(): number {
    return this.viewers.size;
  }

  /** Keeps the upstream socket open without a viewer (the watch). Returns the release. */
  hold(): () => void {
    this.holds++;
    this.cancelGrace();
    let released = false;
    return () => {
      if (released) return;
      released = true;
      this.holds--;
      this.scheduleGrace();
    };
  }

  /** Every redacted controller frame, as text (the watch reads them). Returns the unsubscribe. */
  onFrame(cb: (frame: string) => void): () => void {
    this.frameListeners.add(cb);
    return () => this.frameListeners.delete(cb);
  }

  /** Called once when the hub ends. Returns the unsubscribe. */
  onEnded(cb: () => void): () => void {
    if (this.ended) {
      queueMicrotask(cb);
      return () => undefined;
    }
    this.endListeners.add(cb);
    return () => this.endListeners.delete(cb);
  }

  /** A browser socket (already accepted and authorized) joins. */
  add(ws: WebSocket): void {
    if (this.ended) {
      ws.close(CLOSED_BY_CONTROLLER, 'the controller closed the socket');
      return;
    }
    this.cancelGrace();
    const v: Viewer = {
      ws,
      pending: new Map(),
      rateMs: null,
      lastLatestAt: 0,
      timer: null,
      sent: null,
      wantsNext: false,
      events: [],
      windowStart: this.now(),
      windowCount: 0,
    };
    this.viewers.add(v);
    this.stats.viewers = this.viewers.size;
    ws.on('message', (data: RawData, isBinary: boolean) => this.fromBrowser(v, data, isBinary));
    const leave = (): void => this.remove(v);
    ws.once('close', leave);
    ws.once('error', leave);
    if (this.decl.kind === 'model') {
      if (this.model) this.sendModelFirst(v, this.model);
    } else {
      for (const f of this.replayLatest.values()) this.send(v, f.data, f.isBinary);
      for (const f of this.replayEvents) this.send(v, f.data, f.isBinary);
      for (const f of this.beforeFirstViewer ?? []) this.send(v, f.data, f.isBinary);
      this.beforeFirstViewer = null;
      this.updateUpstreamRate();
    }
  }

  /** Closes every browser socket and the upstream one (gateway closing). */
  close(code: number, reason: string): void {
    this.upstream.close(1000, 'the console closed the socket');
    this.end(code, reason);
  }

  // ---------------------------------------------------------------- upstream → browsers

  /**
   * A controller frame: queued, coalesced with a waiting one of its key when the family says it
   * supersedes it, and handled in turns of at most `batchFrames`/`batchBytes` (redaction, the
   * watch, the browsers); the event loop runs between turns. ws hands over every frame of a read
   * at once, whatever `pause()`: a burst of 20,000 costs here only its classification.
   */
  private fromUpstream(raw: Buffer, isBinary: boolean): void {
    if (this.ended) return;
    this.lastHeard = this.now();
    this.stats.framesIn++;
    this.rateBound();
    const decl = this.decl;
    const cls: FrameClass | null =
      decl.kind === 'fanout' ? (isBinary ? { kind: 'event' } : decl.classify(text(raw))) : null;
    if (cls?.kind !== 'latest' && ++this.windowEvents === this.limits.maxFramesPerSecond) {
      if (++this.floodWindows >= this.limits.floodSeconds) return this.flooded();
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
      return this.flooded();
    this.drain();
  }

  /** A sustained flood: the controller's socket is closed, the viewers told (1011) and they reconnect. */
  private flooded(): void {
    this.opts.warn?.('the controller sends frames faster than they can be handled: its socket is closed');
    this.upstream.close(1008, 'too many frames');
    this.end(CLOSED_BY_CONTROLLER, 'the controller flooded its socket');
  }

  /** Handles waiting frames up to this turn's budget; the rest in the next turn. */
  private drain(): void {
    while (this.head < this.inbox.length && !this.ended) {
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
      this.handle(f);
    }
    if (this.head >= this.inbox.length) {
      this.inbox = [];
      this.head = 0;
      this.waitingLatest.clear();
    }
    if ((this.turnFrames || this.head < this.inbox.length) && !this.turnTimer && !this.ended) {
      this.turnTimer = setImmediate(() => {
        this.turnTimer = null;
        this.turnFrames = 0;
        this.turnBytes = 0;
        this.drain();
      });
    }
  }

  private handle(f: Inbound): void {
    const data = this.opts.toClient ? this.opts.toClient(f.raw, f.isBinary) : f.raw;
    if (this.frameListeners.size && !f.isBinary) {
      const t = text(data);
      for (const cb of this.frameListeners) cb(t);
    }
    if (this.ended) return;
    if (this.decl.kind === 'model') this.modelFrame(this.decl, data, f.isBinary);
    else this.fanoutFrame(f.cls ?? { kind: 'event' }, data, f.isBinary);
  }

  /** A flooding controller is paused for the rest of the second (its frames wait in TCP). */
  private rateBound(): void {
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

  private fanoutFrame(c: FrameClass, data: Buffer, isBinary: boolean): void {
    const frame = { data, isBinary };
    if (c.kind === 'latest') {
      if (c.replay) this.replayLatest.set(c.key, frame);
      for (const v of this.viewers) this.offerLatest(v, c.key, frame);
      return;
    }
    if (c.replay) {
      this.replayEvents.push(frame);
      if (this.replayEvents.length > this.limits.replayEvents) this.replayEvents.shift();
    } else if (this.beforeFirstViewer && this.beforeFirstViewer.length < this.limits.replayEvents)
      this.beforeFirstViewer.push(frame);
    for (const v of this.viewers) {
      // Whatever state was waiting goes first: the event came after it.
      this.flushLatest(v, true);
      this.send(v, data, isBinary);
    }
  }

  private offerLatest(v: Viewer, key: string, frame: { data: Buffer; isBinary: boolean }): void {
    if (v.pending.has(key)) this.stats.coalesced++;
    v.pending.set(key, frame);
    this.flushLatest(v, false);
  }

  /** Sends the waiting `latest` frames when the browser's rate and send buffer allow. */
  private flushLatest(v: Viewer, force: boolean): void {
    if (!v.pending.size || v.ws.readyState !== WebSocket.OPEN) return;
    const t = this.now();
    const rate = v.rateMs ?? (this.decl.kind === 'fanout' ? (this.decl.defaultRateMs ?? 0) : 0);
    const wait = v.lastLatestAt + rate - t;
    const slow = v.ws.bufferedAmount > this.limits.highWaterBytes;
    if (!force && (wait > 0 || slow)) {
      if (!v.timer) {
        v.timer = setTimeout(
          () => {
            v.timer = null;
            this.flushLatest(v, false);
          },
          Math.max(wait, slow ? 50 : 0, 1),
        );
      }
      return;
    }
    const frames = [...v.pending.values()];
    v.pending.clear();
    v.lastLatestAt = t;
    for (const f of frames) this.send(v, f.data, f.isBinary);
  }

  private modelFrame(decl: ModelStreamDecl, data: Buffer, isBinary: boolean): void {
    const frame = text(data);
    if (isBinary) return;
    if (decl.ping?.isPong(frame)) return;
    const before = this.model;
    if (!before) {
      const full = decl.full(frame);
      if (full instanceof Error) {
        this.opts.warn?.(`the controller's first frame is not a model: ${full.message}`);
        this.upstream.close(1002, 'not a model');
        this.end(BAD_DATA_FROM_CONTROLLER, 'the controller sent something else than its model');
        return;
      }
      this.model = full;
      this.upstream.send(decl.ack);
      for (const v of this.viewers) this.sendModelFirst(v, full);
      return;
    }
    const r = decl.apply(before, frame);
    this.upstream.send(decl.ack);
    if (r instanceof Error) {
      // One bad patch: the model may now differ from the controller's. Everyone starts again.
      this.opts.warn?.(`a model patch from the controller was refused: ${r.message}`);
      this.upstream.close(1002, 'bad patch');
      this.end(BAD_DATA_FROM_CONTROLLER, 'the controller sent a patch that does not apply');
      return;
    }
    this.model = r.model;
    for (const v of this.viewers) {
      if (v.sent === null) continue;
      if (r.events.length) {
        v.events.push(...r.events);
        if (v.events.length > this.limits.pendingEvents)
          v.events.splice(0, v.events.length - this.limits.pendingEvents);
      }
      if (!v.wantsNext) continue;
      if (v.sent === before && v.events.length === r.events.length) {
        // Up to date: the controller's own patch is exactly what this browser needs.
        this.sendPatch(v, data, r.model);
      } else this.sendDiff(decl, v);
    }
  }

  private sendModelFirst(v: Viewer, model: JsonRecord): void {
    if (this.decl.kind !== 'model') return;
    v.sent = model;
    v.wantsNext = false;
    v.events = [];
    this.send(v, Buffer.from(this.decl.first(model), 'utf8'), false);
  }

  private sendDiff(decl: ModelStreamDecl, v: Viewer): void {
    const model = this.model;
    if (!model || v.sent === null || (v.sent === model && !v.events.length)) return;
    const frame = decl.diff(v.sent, model, v.events);
    this.sendPatch(v, Buffer.from(frame, 'utf8'), model);
  }

  private sendPatch(v: Viewer, data: Buffer, model: JsonRecord): void {
    v.sent = model;
    v.wantsNext = false;
    v.events = [];
    this.send(v, data, false);
  }

  private send(v: Viewer, data: Buffer, isBinary: boolean): void {
    if (v.ws.readyState !== WebSocket.OPEN) return;
    if (v.ws.bufferedAmount + data.length > this.limits.hardLimitBytes) {
      this.stats.slowClosed++;
      v.ws.close(1013, 'too slow for the machine’s updates: reconnect');
      this.remove(v);
      return;
    }
    this.stats.framesOut++;
    v.ws.send(data, { binary: isBinary });
  }

  // ---------------------------------------------------------------- browsers → here

  private fromBrowser(v: Viewer, data: RawData, isBinary: boolean): void {
    const t = this.now();
    if (t - v.windowStart >= 1000) {
      v.windowStart = t;
      v.windowCount = 0;
    }
    if (++v.windowCount > this.limits.maxBrowserFramesPerSecond) {
      v.ws.close(1008, 'too many frames');
      this.remove(v);
      return;
    }
    if (isBinary) return;
    const buf = Buffer.isBuffer(data) ? data : Array.isArray(data) ? Buffer.concat(data) : Buffer.from(data);
    if (buf.length > 1024) return;
    const frame = text(buf);
    const decl = this.decl;
    if (decl.kind === 'model') {
      const r = decl.fromBrowser(frame);
      if (!r) return;
      if ('reply' in r) {
        if (v.ws.readyState === WebSocket.OPEN) v.ws.send(r.reply);
        return;
      }
      v.wantsNext = true;
      this.sendDiff(decl, v);
      return;
    }
    const r = decl.fromBrowser?.(frame) ?? null;
    if (!r) return;
    if ('reply' in r) {
      if (v.ws.readyState === WebSocket.OPEN) v.ws.send(r.reply);
      return;
    }
    v.rateMs = Math.max(0, r.rateMs);
    this.updateUpstreamRate();
    this.flushLatest(v, false);
  }

  /** The fastest rate any viewer wants goes upstream (when the family has a rate frame). */
  private updateUpstreamRate(): void {
    if (this.decl.kind !== 'fanout' || !this.decl.upstreamRate || this.ended) return;
    let fastest = Infinity;
    for (const v of this.viewers) if (v.rateMs !== null) fastest = Math.min(fastest, v.rateMs);
    if (!Number.isFinite(fastest)) return; // nobody asked: keep the last one
    if (fastest === this.upstreamRateMs) return;
    this.upstreamRateMs = fastest;
    this.upstream.send(this.decl.upstreamRate(fastest));
  }

  // ---------------------------------------------------------------- leaving, ending

  private remove(v: Viewer): void {
    if (!this.viewers.delete(v)) return;
    if (v.timer) clearTimeout(v.timer);
    this.stats.viewers = this.viewers.size;
    this.updateUpstreamRate();
    this.scheduleGrace();
  }

  private scheduleGrace(): void {
    if (this.ended || this.viewers.size || this.holds || this.graceTimer) return;
    this.graceTimer = setTimeout(() => {
      this.graceTimer = null;
      if (this.viewers.size || this.holds) return;
      this.upstream.close(1000, 'nobody is watching');
      this.end(1000, 'nobody is watching');
    }, this.decl.graceMs);
  }

  private cancelGrace(): void {
    if (this.graceTimer) clearTimeout(this.graceTimer);
    this.graceTimer = null;
  }

  private closeWords(code: number, reason: string): string {
    return reason
      ? `the controller closed the socket: ${reason}`.slice(0, 120)
      : `the controller closed the socket (${code})`;
  }

  private end(code: number, reason: string): void {
    if (this.ended) return;
    this.ended = true;
    this.cancelGrace();
    if (this.pingTimer) clearInterval(this.pingTimer);
    if (this.pausedUntil) clearTimeout(this.pausedUntil);
    if (this.turnTimer) clearImmediate(this.turnTimer);
    this.turnTimer = null;
    this.inbox = [];
    this.head = 0;
    this.waitingLatest.clear();
    for (const v of [...this.viewers]) {
      if (v.timer) clearTimeout(v.timer);
      if (v.ws.readyState === WebSocket.OPEN || v.ws.readyState === WebSocket.CONNECTING)
        v.ws.close(code, reason.slice(0, 120));
    }
    this.viewers.clear();
    this.stats.viewers = 0;
    this.frameListeners.clear();
    this.opts.onEnd?.();
    for (const cb of [...this.endListeners]) cb();
    this.endListeners.clear();
  }
}

/**
 * The query that goes upstream with a shared stream and tells its sockets apart: only the
 * parameters the family declares (`query`), each with one of its declared values, in the declared
 * order; whatever else a browser sends is dropped. An Error (400 for the browser): a declared
 * parameter repeated or with a value outside its set.
 */
export function streamQuery(decl: SharedStreamDecl, rawQuery: string): string | Error {
  const given = new URLSearchParams(rawQuery);
  const out = new URLSearchParams();
  for (const [name, values] of Object.entries(decl.query ?? {})) {
    const v = given.getAll(name);
    if (v.length === 0) continue;
    if (v.length > 1) return new Error(`"${name}" given more than once`);
    const value = v[0] ?? '';
    if (!values.includes(value)) return new Error(`"${name}" may only be one of: ${values.join(', ')}`);
    out.set(name, value);
  }
  return out.toString();
}

/** The hubs of a gateway, by machine and stream. */
export class StreamHubs {
  private readonly hubs = new Map<string, StreamHub>();
  /** Browser sockets that joined a shared stream, per machine (tests, benchmarks). */
  private readonly joins = new Map<string, number>();
  /** Hubs being opened: later viewers wait for the same opening. */
  private readonly opening = new Map<string, Promise<StreamHub | { status: number; error: string }>>();

  /** `query`: the declared query only (`streamQuery`), never the browser's own string. */
  static key(machine: string, path: string, query: string): string {
    return `${machine}\u0000${path}\u0000${query}`;
  }

  /**
   * The open hub for `key`, or a new one: `open` connects the controller's socket once, however
   * many viewers ask at the same time.
   */
  async get(
    key: string,
    open: () => Promise<{ hub: StreamHub } | { status: number; error: string }>,
  ): Promise<StreamHub | { status: number; error: string }> {
    const have = this.hubs.get(key);
    if (have?.open) return have;
    const pending = this.opening.get(key);
    if (pending) return pending;
    const p = open().then((r) => {
      this.opening.delete(key);
      if ('status' in r) return r;
      this.hubs.set(key, r.hub);
      return r.hub;
    });
    this.opening.set(key, p);
    return p;
  }

  /** A browser socket of `machine` joined one of its shared streams. */
  noteJoin(machine: string): void {
    this.joins.set(machine, (this.joins.get(machine) ?? 0) + 1);
  }

  /** Shared-stream counts of a machine: browser sockets that joined so far, hubs open now. */
  stats(machine: string): { joined: number; open: number } {
    return { joined: this.joins.get(machine) ?? 0, open: this.ofMachine(machine).length };
  }

  /** Forget a hub that ended (its `onEnd`). */
  forget(key: string, hub: StreamHub): void {
    if (this.hubs.get(key) === hub) this.hubs.delete(key);
  }

  find(key: string): StreamHub | undefined {
    const h = this.hubs.get(key);
    return h?.open ? h : undefined;
  }

  /** Every open hub of a machine (the watch, stats). */
  ofMachine(machine: string): StreamHub[] {
    const out: StreamHub[] = [];
    for (const [k, h] of this.hubs) if (k.startsWith(`${machine}\u0000`) && h.open) out.push(h);
    return out;
  }

  get size(): number {
    let n = 0;
    for (const h of this.hubs.values()) if (h.open) n++;
    return n;
  }

  closeAll(code: number, reason: string): void {
    for (const h of this.hubs.values()) h.close(code, reason);
    this.hubs.clear();
  }
}

// ---------------------------------------------------------------- upstream adapters

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
