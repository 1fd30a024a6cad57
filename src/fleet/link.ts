import { pageScheduler, type Cancel, type Deadline, type Scheduler } from './kernel/scheduler';
import { wsUrlFor } from './origin';
/**
 * Per-machine link machinery: backoff, a poll scheduler that never overlaps, page visibility,
 * and a WebSocket that reconnects. Each machine has its own instances: one dead controller
 * never slows another.
 */

export interface BackoffOptions {
  baseMs?: number;
  maxMs?: number;
  /** 0..1 share of the delay that is random (full jitter = 1). */
  jitter?: number;
  random?: () => number;
}

/** Exponential backoff with jitter, about 1 s to 30 s. `attempt` counts from 0. */
export function backoffDelay(attempt: number, opts: BackoffOptions = {}): number {
  const base = opts.baseMs ?? 1000;
  const max = opts.maxMs ?? 30_000;
  const jitter = opts.jitter ?? 0.3;
  const random = opts.random ?? Math.random;
  const raw = Math.min(max, base * 2 ** Math.max(0, attempt));
  const low = raw * (1 - jitter);
  return Math.round(low + (raw - low) * random());
}

/** Page visibility, injectable for tests and Node. */
export interface Visibility {
  hidden(): boolean;
  subscribe(fn: () => void): () => void;
}

export const documentVisibility: Visibility = {
  hidden: () => typeof document !== 'undefined' && document.visibilityState === 'hidden',
  subscribe: (fn) => {
    if (typeof document === 'undefined') return () => undefined;
    document.addEventListener('visibilitychange', fn);
    return () => document.removeEventListener('visibilitychange', fn);
  },
};

export const alwaysVisible: Visibility = { hidden: () => false, subscribe: () => () => undefined };

/**
 * The delay to the next moment on the shared grid of `periodMs` (multiples of it since the epoch),
 * between half a period and one and a half from `now`. Polls that follow it start in the same
 * moment on every machine of a page (and on every page of the shop): their answers arrive
 * together and are drawn in one frame instead of one each, and the console server's read sharing
 * finds two screens' identical reads at the same time (issue 16: one clock, not a timer per tile).
 */
export function gridDelay(now: number, periodMs: number): number {
  if (!(periodMs > 0)) return 0;
  return Math.ceil((now + periodMs / 2) / periodMs) * periodMs - now;
}

/** While the page is hidden a machine is polled at most once per this many ms. */
export const HIDDEN_POLL_MS = 10_000;

export interface PollerOptions {
  /** The poll: resolves when done. A poll is never started while the previous one runs. */
  run: () => Promise<void>;
  /** Interval (ms) measured from the end of one poll to the start of the next. */
  intervalMs: () => number;
  visibility?: Visibility;
  /** Called with the error of a failed poll; the poller keeps going at `retryDelayMs`. */
  onError?: (e: unknown) => void;
  /** Delay after a failed poll; defaults to the interval. */
  retryDelayMs?: (failures: number) => number;
  /**
   * True: after a good poll the next starts on the shared grid of the interval (`gridDelay`)
   * rather than exactly one interval after the end (a machine shown only on a tile). Retries and
   * kicks are never moved.
   */
  aligned?: () => boolean;
  now?: () => number;
  /** Whose timers (default the page's scheduler: polls due at one moment share one timer). */
  scheduler?: Scheduler;
}

/**
 * A poll scheduler: one timer, one poll in flight at most, slower while the page is hidden
 * (never more often than HIDDEN_POLL_MS), and `kick()` to poll now (when no poll is running).
 */
export class Poller {
  private timer: Cancel | null = null;
  private running = false;
  /** A kick arrived while a poll was in flight: poll again as soon as it ends. */
  private kicked = false;
  private stopped = true;
  /** Counts stops: a poll of an earlier run neither blocks nor schedules the next run's polls. */
  private generation = 0;
  private failures = 0;
  private unsubscribe: (() => void) | null = null;
  private readonly vis: Visibility;
  private readonly scheduler: Scheduler;
  /** Count of polls started, for tests and benchmarks. */
  started = 0;

  constructor(private readonly opts: PollerOptions) {
    this.vis = opts.visibility ?? documentVisibility;
    this.scheduler = opts.scheduler ?? pageScheduler;
  }

  start(delayMs = 0): void {
    if (!this.stopped) return;
    this.stopped = false;
    this.unsubscribe = this.vis.subscribe(() => {
      // Back on screen: refresh soon rather than waiting out a long hidden interval.
      if (!this.vis.hidden() && !this.running) this.schedule(0);
    });
    this.schedule(delayMs);
  }

  stop(): void {
    this.stopped = true;
    this.kicked = false;
    this.running = false;
    this.generation++;
    this.timer?.();
    this.timer = null;
    this.unsubscribe?.();
    this.unsubscribe = null;
  }

  get isRunning(): boolean {
    return !this.stopped;
  }

  /** Poll as soon as possible (after the one in flight, if any). */
  kick(): void {
    if (this.stopped) return;
    // The poll in flight may have read the state before the change the kick is about (a command
    // just sent): poll once more right after it rather than waiting a whole interval.
    if (this.running) this.kicked = true;
    else this.schedule(0);
  }

  private nextDelay(): number {
    const base =
      this.failures > 0 && this.opts.retryDelayMs
        ? this.opts.retryDelayMs(this.failures)
        : this.opts.intervalMs();
    const delay = this.vis.hidden() ? Math.max(base, HIDDEN_POLL_MS) : base;
    if (this.failures > 0 || !this.opts.aligned?.()) return delay;
    return gridDelay((this.opts.now ?? Date.now)(), delay);
  }

  private schedule(delayMs: number): void {
    if (this.stopped) return;
    this.timer?.();
    this.timer = this.scheduler.after(delayMs, () => void this.tick());
  }

  private async tick(): Promise<void> {
    this.timer = null;
    if (this.stopped || this.running) return;
    const gen = this.generation;
    this.running = true;
    this.started++;
    try {
      await this.opts.run();
      if (gen === this.generation) this.failures = 0;
    } catch (e) {
      if (gen === this.generation) {
        this.failures++;
        this.opts.onError?.(e);
      }
    } finally {
      if (gen === this.generation) this.running = false;
    }
    if (this.stopped || gen !== this.generation) return;
    if (this.kicked) {
      this.kicked = false;
      this.schedule(0);
    } else if (!this.timer) this.schedule(this.nextDelay());
  }
}

export type SocketData = string | ArrayBuffer | Blob;

export interface SocketLinkOptions {
  /** URL (same origin): "/machines/<id>/machine?sessionKey=…" — made absolute ws(s):// here. */
  url: () => string;
  onOpen?: () => void;
  onMessage: (data: string) => void;
  /** Every close, with the code; return false to stop reconnecting. */
  onClose?: (code: number, reason: string) => boolean | void;
  backoff?: BackoffOptions;
  /** Start the first connection immediately (default) or wait for connect(). */
  autoConnect?: boolean;
  /**
   * Hand messages over in batches, once per animation frame (or at once when the page has no
   * frames to draw), in order, none dropped: a flood of frames then costs one render per frame
   * instead of one per message, and the page stays responsive. Off by default.
   */
  coalesce?: boolean;
  /** How the link proves it is alive (see HeartbeatPolicy); without one, only a close counts. */
  heartbeat?: HeartbeatPolicy;
  /**
   * Polling while the socket does not deliver (closed, reconnecting, dead): started when the
   * socket goes down, stopped by the first message of a new socket. The socket stays the source.
   */
  fallback?: { run: () => Promise<void>; intervalMs: number; visibility?: Visibility };
  now?: () => number;
  /** Whose timers (default the page's scheduler). */
  scheduler?: Scheduler;
}

/**
 * A socket's declared liveness rule, so no family runs a watchdog of its own. Silence for
 * `silenceMs` either sends `ping` (Duet: `PING\n`) and waits `answerMs` for any message, or,
 * without a ping, is death by itself (Prunt: a status every second, 10 s silence is dead). A
 * socket whose first message does not come within `firstMessageMs` of connecting is dead too.
 * Dead: `onDead(reason)`, then the socket restarts with backoff.
 */
export interface HeartbeatPolicy {
  silenceMs: number;
  ping?: string;
  /** After a ping, how long any message may take (default `silenceMs`). */
  answerMs?: number;
  /** From connect to the first message (default `silenceMs` + `answerMs`). */
  firstMessageMs?: number;
  onDead?: (reason: string) => void;
}

/** Runs `fn` at the next animation frame, or soon when there is none (hidden page, Node). */
function nextFrame(fn: () => void): void {
  const raf = globalThis.requestAnimationFrame as ((cb: () => void) => number) | undefined;
  const hidden = typeof document !== 'undefined' && document.visibilityState === 'hidden';
  if (raf && !hidden) raf(fn);
  else setTimeout(fn, 0);
}

/**
 * A WebSocket that reconnects with backoff. Sockets are created from `globalThis.WebSocket`
 * at connect time (msw's ws.link patches it). It never buffers outgoing messages while closed:
 * `send` returns false and the caller decides.
 */
export class SocketLink {
  private ws: WebSocket | null = null;
  private attempt = 0;
  private timer: Cancel | null = null;
  private closedByUs = false;
  /** Messages waiting for the next frame (coalesce), and whether a flush is scheduled. */
  private batch: string[] = [];
  private flushing = false;
  /** When the next reconnect is due (ms since epoch) or null. */
  retryAt: number | null = null;
  /** Heartbeat bookkeeping: when this socket connected, last heard, pinged; whether it spoke yet. */
  private connectedAt = 0;
  private lastMessageAt = 0;
  private pingSentAt: number | null = null;
  private gotFirst = false;
  /** The heartbeat rule's next moment: one deadline, moved on by messages (no timer each). */
  private readonly watch: Deadline;
  private readonly fallback: Poller | null;
  private readonly now: () => number;
  private readonly scheduler: Scheduler;

  constructor(private readonly opts: SocketLinkOptions) {
    this.now = opts.now ?? Date.now;
    this.scheduler = opts.scheduler ?? pageScheduler;
    this.watch = this.scheduler.deadline({
      now: this.now,
      // Only while a socket of ours is up (a closed socket's reconnect has its own timer).
      due: () => (this.closedByUs || !this.ws ? null : this.heartbeatDue()),
      fire: () => this.checkHeartbeat(),
    });
    this.fallback = opts.fallback
      ? new Poller({
          run: opts.fallback.run,
          intervalMs: () => opts.fallback?.intervalMs ?? 1000,
          visibility: opts.fallback.visibility,
          scheduler: this.scheduler,
        })
      : null;
    if (opts.autoConnect !== false) this.connect();
  }

  /** True while the fallback poll runs in place of the socket. */
  get polling(): boolean {
    return this.fallback?.isRunning ?? false;
  }

  /** Silence for `silenceMs`: ping or death; a late first message: death (HeartbeatPolicy). */
  private checkHeartbeat(): void {
    const hb = this.opts.heartbeat;
    if (!hb || this.closedByUs || !this.ws) return;
    const now = this.now();
    const answerMs = hb.answerMs ?? hb.silenceMs;
    if (!this.gotFirst) {
      if (now - this.connectedAt >= (hb.firstMessageMs ?? hb.silenceMs + answerMs))
        this.dead(this.open ? 'No data after connecting' : 'The live connection did not open');
      return;
    }
    if (this.pingSentAt !== null) {
      if (now - this.pingSentAt >= answerMs) this.dead(`No answer to ${hb.ping?.trim() ?? 'a ping'}`);
      return;
    }
    if (now - this.lastMessageAt < hb.silenceMs) return;
    if (hb.ping !== undefined && this.send(hb.ping)) this.pingSentAt = now;
    else this.dead(`No data for ${Math.round(hb.silenceMs / 1000)} s`);
  }

  private dead(reason: string): void {
    this.opts.heartbeat?.onDead?.(reason);
    if (!this.closedByUs) this.restart();
  }

  /** When the heartbeat rule next has something to decide (null: no rule). */
  private heartbeatDue(): number | null {
    const hb = this.opts.heartbeat;
    if (!hb) return null;
    const answerMs = hb.answerMs ?? hb.silenceMs;
    if (!this.gotFirst) return this.connectedAt + (hb.firstMessageMs ?? hb.silenceMs + answerMs);
    if (this.pingSentAt !== null) return this.pingSentAt + answerMs;
    return this.lastMessageAt + hb.silenceMs;
  }

  /** The heartbeat's deadline set anew for its moment (a new socket). */
  private startWatch(): void {
    this.watch.update(true);
  }

  private stopWatch(): void {
    this.watch.cancel();
  }

  private heard(): void {
    this.lastMessageAt = this.now();
    const answered = this.pingSentAt !== null;
    this.pingSentAt = null;
    if (!this.gotFirst) {
      this.gotFirst = true;
      this.fallback?.stop();
    }
    // A later moment keeps the timer (it fires early and is set for the rest); a ping answered
    // sets it anew.
    this.watch.update(answered);
  }

  /** The socket stopped delivering: poll in its place (when declared) until it is back. */
  private socketDown(): void {
    if (this.fallback && !this.closedByUs && !this.fallback.isRunning) this.fallback.start(0);
  }

  get open(): boolean {
    return this.ws !== null && this.ws.readyState === 1;
  }

  private opened = 0;

  /** Counts the sockets this link opened: what was said on one socket belongs to it only. */
  get generation(): number {
    return this.opened;
  }

  connect(): void {
    this.opened++;
    this.closedByUs = false;
    this.timer?.();
    this.timer = null;
    this.retryAt = null;
    // One socket at a time: a socket still connecting (or open) is dropped, never orphaned.
    this.drop(this.ws);
    this.ws = null;
    const url = absoluteWsUrl(this.opts.url());
    this.connectedAt = this.now();
    this.lastMessageAt = this.connectedAt;
    this.pingSentAt = null;
    this.gotFirst = false;
    let ws: WebSocket;
    try {
      ws = new globalThis.WebSocket(url);
    } catch {
      this.stopWatch();
      this.scheduleReconnect();
      return;
    }
    this.ws = ws;
    this.startWatch();
    ws.onopen = () => {
      this.attempt = 0;
      this.opts.onOpen?.();
    };
    ws.onmessage = (ev: MessageEvent) => {
      if (this.ws !== ws) return;
      this.heard();
      const d: unknown = ev.data;
      if (typeof d === 'string') this.deliver(d);
      else if (d instanceof ArrayBuffer) this.deliver(new TextDecoder().decode(d));
      else if (d instanceof Blob) void d.text().then((t) => this.deliver(t));
    };
    ws.onclose = (ev: CloseEvent) => {
      if (this.ws !== ws) return;
      this.ws = null;
      const again = this.opts.onClose?.(ev.code, ev.reason);
      if (!this.closedByUs && again !== false) {
        this.socketDown();
        this.scheduleReconnect();
      } else this.stopWatch();
    };
    ws.onerror = () => {
      // onclose follows.
    };
  }

  private deliver(text: string): void {
    if (!this.opts.coalesce) {
      this.opts.onMessage(text);
      return;
    }
    this.batch.push(text);
    if (this.flushing) return;
    this.flushing = true;
    nextFrame(() => {
      this.flushing = false;
      const batch = this.batch;
      this.batch = [];
      // After close() (the session stopped) nothing is handed over; a socket that dropped by
      // itself still delivers what it received (an alarm just before the drop counts).
      if (this.closedByUs) return;
      for (const m of batch) this.opts.onMessage(m);
    });
  }

  send(data: string): boolean {
    if (!this.ws || this.ws.readyState !== 1) return false;
    this.ws.send(data);
    return true;
  }

  /** Drop the current socket and reconnect after backoff (dead link detected by the caller). */
  restart(): void {
    this.drop(this.ws);
    this.ws = null;
    this.socketDown();
    // A reconnect already pending stays the only one (no second timer, no second socket).
    if (!this.timer) this.scheduleReconnect();
  }

  /** Detaches and closes a socket that is no longer ours. */
  private drop(ws: WebSocket | null, code?: number): void {
    if (!ws) return;
    ws.onopen = null;
    ws.onclose = null;
    ws.onmessage = null;
    try {
      ws.close(code);
    } catch {
      /* ignore */
    }
  }

  close(): void {
    this.closedByUs = true;
    this.stopWatch();
    this.fallback?.stop();
    this.timer?.();
    this.timer = null;
    this.retryAt = null;
    this.drop(this.ws, 1000);
    this.ws = null;
  }

  private scheduleReconnect(): void {
    if (this.closedByUs) return;
    const delay = backoffDelay(this.attempt++, this.opts.backoff);
    this.retryAt = this.now() + delay;
    this.timer = this.scheduler.after(delay, () => {
      this.timer = null;
      this.connect();
    });
  }
}

export function absoluteWsUrl(url: string): string {
  return wsUrlFor(url);
}
