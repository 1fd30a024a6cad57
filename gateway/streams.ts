import { WebSocket, type RawData } from 'ws';
import type {
  FrameClass,
  JsonRecord,
  JsonValue,
  ModelStreamDecl,
  SharedStreamDecl,
} from '../src/fleet/contract';
import { UpstreamInbox, type Inbound } from './stream-inbox';
import {
  DEFAULT_STREAM_LIMITS,
  type HubOptions,
  type HubStats,
  type StreamLimits,
  UPSTREAM_CHECK_MS,
  UPSTREAM_DEAD_AFTER_PINGS,
} from './stream-options';
import type { UpstreamSocket } from './stream-upstream';

/**
 * Shared controller sockets: one upstream socket per machine and declared stream, whatever the
 * number of viewers (`SharingHints.streams`, src/fleet/contract.ts). A fan-out or a model stream;
 * the rules (slow browsers, floods, keep-alive, close codes) are in gateway/README.md, "One
 * upstream per machine". Nothing waits on a browser: a slow one never slows the others.
 */

export {
  DEFAULT_STREAM_LIMITS,
  type HubOptions,
  type HubStats,
  type StreamLimits,
  UPSTREAM_CHECK_MS,
  UPSTREAM_DEAD_AFTER_PINGS,
} from './stream-options';
export { simUpstream, wsUpstream, type UpstreamSocket } from './stream-upstream';

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

function text(data: Buffer): string {
  return data.toString('utf8');
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
  /** Controller frames waiting for their turn (stream-inbox.ts). */
  private readonly inbox: UpstreamInbox;

  constructor(
    readonly decl: SharedStreamDecl,
    private readonly upstream: UpstreamSocket,
    private readonly opts: HubOptions = {},
  ) {
    this.limits = { ...DEFAULT_STREAM_LIMITS, ...opts.limits };
    this.now = opts.now ?? Date.now;
    this.lastHeard = this.now();
    this.inbox = new UpstreamInbox(this.limits, this.now, upstream, this.stats, {
      handle: (f) => this.handle(f),
      flooded: () => this.flooded(),
    });
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

  /** A controller frame: classified once, then queued for its turn (stream-inbox.ts). */
  private fromUpstream(raw: Buffer, isBinary: boolean): void {
    if (this.ended) return;
    this.lastHeard = this.now();
    this.stats.framesIn++;
    this.inbox.rateBound();
    const decl = this.decl;
    const cls: FrameClass | null =
      decl.kind === 'fanout' ? (isBinary ? { kind: 'event' } : decl.classify(text(raw))) : null;
    this.inbox.take(raw, isBinary, cls);
  }

  /** A sustained flood: the controller's socket is closed, the viewers told (1011) and they reconnect. */
  private flooded(): void {
    this.opts.warn?.('the controller sends frames faster than they can be handled: its socket is closed');
    this.upstream.close(1008, 'too many frames');
    this.end(CLOSED_BY_CONTROLLER, 'the controller flooded its socket');
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
    this.inbox.stop();
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
