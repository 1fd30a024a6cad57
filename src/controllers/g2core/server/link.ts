import type { OpenPort, PortEvents, PortInfo, PortOpener } from '../../../fleet/server-part';
import {
  BOARD_USB_IDS,
  CTRL,
  DEFAULT_WINDOW,
  MAX_RX_LINE,
  jsonLine,
  parseBoardLine,
  scalarsOf,
  type BoardMessage,
  type Json,
  type JsonObject,
  wireBytes,
} from './protocol';

/**
 * The gateway's one connection to a g2core/TinyG board on a serial port (issue 19): it owns the
 * port, reads lines, and writes with line-mode flow control (protocol-notes.json
 * `linemode_flow_control`). The board is modelled as the firmware is (g2core `xio.cpp`
 * `_scanBuffer`, `controller.cpp` `_dispatch_control`): a JSON request (a line starting with `{`)
 * is a control, answered at once, ahead of the G-code lines waiting in the board, with the
 * planner full and throughout a hold; G-code lines are the queue. So there are two lanes:
 * G-code lines, at most `window` in flight, one more per answer; JSON requests, at most
 * `JSON_LANE` in flight, outside that window. Each `{r}` is matched to what it answers by its
 * content, never by position across the two: a JSON answer names its key, a G-code line's
 * answer names none (or only the echoed `gc`, `n`, `msg`) and answers the oldest G-code line.
 * Single-character controls (`!`, `~`, `%`, ^D, ^X, ENQ) are written at once, always between
 * two whole lines, and take no slot. Nothing is queued while the port is closed and nothing is
 * replayed after a reconnect: a request made then fails at once.
 */

/** JSON requests in flight at once (each is answered at once; this bounds the board's input buffer). */
export const JSON_LANE = 4;

/** Keys a G-code line's answer may carry (`js.echo_json_gcode_block`, line numbers, messages). */
const GCODE_ANSWER_KEYS = new Set(['gc', 'n', 'msg']);

/**
 * The key a JSON line's answer names (`{"xvm":5000}` → `xvm`), lower-cased; null for a G-code
 * line, and for `{"gc":"G0 X1"}`, which the board answers as G-code (`{"r":{}}`, the captures).
 */
export function jsonKeyOf(line: string): string | null {
  if (!line.startsWith('{')) return null;
  const m = /^\{\s*"?([A-Za-z0-9_]+)"?\s*:/.exec(line);
  const k = m?.[1]?.toLowerCase() ?? '';
  return GCODE_ANSWER_KEYS.has(k) ? null : k;
}

/** The port types are every serial part's (src/fleet/server-part.ts). */
export type { OpenPort, PortEvents, PortInfo, PortOpener };

export type LinkState =
  | { state: 'connecting' }
  | { state: 'online'; since: number }
  /** The port does not exist (unplugged), or `auto` found no board. */
  | { state: 'unplugged'; detail: string }
  /** Another program holds the port. */
  | { state: 'busy'; detail: string }
  | { state: 'error'; detail: string }
  | { state: 'closed' };

/** The board could not answer: not connected, gone, reset (`reset`), or silent past a deadline. */
export class LinkDown extends Error {
  constructor(
    message: string,
    readonly reset = false,
  ) {
    super(message);
  }
}

/** A write refused by the last check before the port (a byte outside printable ASCII). */
export class UnsafeBytes extends Error {}

export interface Reply {
  r: JsonObject;
  status: number;
}

interface InFlight {
  line: string;
  /** The key a JSON request expects back (null for a G-code line). */
  key: string | null;
  /** A JSON line (answered at once by the board): a job's is in flight alone. */
  json?: boolean;
  done(reply: Reply | Error): void;
}

/** A line of an operation or job offered by the streamer when a slot is free. */
export interface DataLine {
  line: string;
  done(reply: Reply | Error): void;
}

export interface LinkOptions {
  /** A device path, or 'auto': the first port with a g2core/TinyG USB id. */
  path: string;
  baudRate: number;
  opener: PortOpener;
  window?: number;
  /** After opening, how long to wait for a start-up banner before the setup is sent. */
  bannerWaitMs?: number;
  /** Reconnect attempts: first after this, doubling up to 10 s. */
  retryMs?: number;
  /** A JSON request with no `{r}` within this fails (the line may have reached the board). */
  requestTimeoutMs?: number;
  /** Setup sent on every (re)connect; the answers are awaited before the link is online. */
  setup?: Array<[string, Json]>;
  setTimeout?: (fn: () => void, ms: number) => unknown;
  clearTimeout?: (t: unknown) => void;
  now?: () => number;
}

export interface LinkListener {
  message?(m: BoardMessage): void;
  state?(s: LinkState): void;
  /** A banner came while connected: the board reset (new banner), everything in flight is lost. */
  reset?(info: JsonObject): void;
}

/** Open errors worded for the machine page: the OS says "busy" or "locked" for a held port. */
export function classifyOpenError(e: unknown, path: string): LinkState {
  const msg = e instanceof Error ? e.message : String(e);
  const code = (e as { code?: unknown } | null)?.code;
  if (/Permission denied/i.test(msg) || code === 'EACCES')
    return {
      state: 'error',
      detail: `${path}: no permission to open it (on Linux, add the console's user to the "dialout" group)`,
    };
  if (/lock|busy|EBUSY|Resource temporarily unavailable|Access denied/i.test(msg) || code === 'EBUSY')
    return { state: 'busy', detail: `${path} is held by another program (close it to let Shopdeck connect)` };
  if (/ENOENT|does not exist|No such file|not found|cannot find/i.test(msg) || code === 'ENOENT')
    return { state: 'unplugged', detail: `${path} is not there: the board is unplugged or switched off` };
  return { state: 'error', detail: `${path} cannot be opened: ${msg.slice(0, 200)}` };
}

export function pickBoardPort(ports: PortInfo[]): PortInfo | null {
  return (
    ports.find((p) =>
      BOARD_USB_IDS.some(
        (id) => p.vendorId?.toLowerCase() === id.vendorId && p.productId?.toLowerCase() === id.productId,
      ),
    ) ?? null
  );
}

export class SerialLink {
  private port: OpenPort | null = null;
  private current: LinkState = { state: 'connecting' };
  private rx = '';
  /** G-code lines (and a job's JSON lines) in flight, oldest first: the queue in the board. */
  private inFlight: InFlight[] = [];
  /** JSON requests in flight: answered out of band. */
  private jsonInFlight: InFlight[] = [];
  /** JSON requests waiting for a place in their lane. */
  private urgent: InFlight[] = [];
  private retryTimer: unknown = null;
  private retryMs: number;
  private stopped = false;
  private generation = 0;
  private readonly listeners = new Set<LinkListener>();
  /**
   * The streamer's next line, pulled when a slot is free (null: none now). `inFlight`: the lines
   * in flight now (a job's JSON line waits until it is 0, so it cannot pass the lines before it).
   */
  source: ((inFlight: number) => DataLine | null) | null = null;
  /** When the board last sent a line (any line): how the bridge knows it is alive. */
  lastHeard = 0;
  /** The board's identity from its banner, if one was seen. */
  banner: JsonObject | null = null;
  /** The device actually opened (the resolved path of 'auto'). */
  device: string | null = null;
  /** Every byte written, oldest first, for tests and the developer's log (bounded). */
  readonly written: string[] = [];
  /** Most lines ever in flight at once (tests check the window is never overfilled). */
  maxInFlight = 0;

  private readonly window: number;
  private readonly st: (fn: () => void, ms: number) => unknown;
  private readonly ct: (t: unknown) => void;
  private readonly now: () => number;

  constructor(private readonly opts: LinkOptions) {
    this.window = Math.max(1, opts.window ?? DEFAULT_WINDOW);
    this.retryMs = opts.retryMs ?? 1000;
    this.st = opts.setTimeout ?? ((fn, ms) => setTimeout(fn, ms));
    this.ct = opts.clearTimeout ?? ((t) => clearTimeout(t as ReturnType<typeof setTimeout>));
    this.now = opts.now ?? Date.now;
  }

  get state(): LinkState {
    return this.current;
  }

  get online(): boolean {
    return this.current.state === 'online';
  }

  listen(l: LinkListener): () => void {
    this.listeners.add(l);
    return () => this.listeners.delete(l);
  }

  start(): void {
    this.stopped = false;
    void this.connect();
  }

  async stop(): Promise<void> {
    this.stopped = true;
    if (this.retryTimer !== null) this.ct(this.retryTimer);
    this.retryTimer = null;
    const p = this.port;
    this.drop('the gateway closed the port');
    this.setState({ state: 'closed' });
    if (p) await p.close().catch(() => undefined);
  }

  private setState(s: LinkState): void {
    this.current = s;
    for (const l of this.listeners) l.state?.(s);
  }

  private async connect(): Promise<void> {
    if (this.stopped || this.port) return;
    const gen = ++this.generation;
    this.setState({ state: 'connecting' });
    let path = this.opts.path;
    try {
      if (path === 'auto') {
        const found = pickBoardPort(await this.opts.opener.list());
        if (!found) {
          this.failOpen({
            state: 'unplugged',
            detail: 'no g2core or TinyG board found on USB (plug it in, or name its port in "serial")',
          });
          return;
        }
        path = found.path;
      }
      const port = await this.opts.opener.open(path, this.opts.baudRate, {
        data: (chunk) => {
          if (gen === this.generation) this.onData(chunk);
        },
        closed: (why) => {
          if (gen === this.generation) this.lost(why);
        },
      });
      if (this.stopped || gen !== this.generation) {
        await port.close().catch(() => undefined);
        return;
      }
      this.port = port;
      this.device = path;
      this.rx = '';
    } catch (e) {
      this.failOpen(classifyOpenError(e, path));
      return;
    }
    // Boards that reset when the port opens (TinyG, the Due's programming port) send their banner
    // first: a request written before it would be lost. Wait for it, briefly.
    await this.bannerOrTimeout(gen);
    if (gen !== this.generation || !this.port) return;
    // Setup: the reports the bridge reads (status reports on, at the rate of the captures).
    try {
      for (const [k, v] of this.opts.setup ?? []) await this.request(k, v, true);
    } catch (e) {
      if (gen !== this.generation || !this.port) return;
      // A board that does not answer its setup is not usable: close and try again later.
      const p = this.port;
      this.port = null;
      this.drop('setup failed');
      await p.close().catch(() => undefined);
      this.failOpen({
        state: 'error',
        detail: `${path}: the board did not answer (${e instanceof Error ? e.message : String(e)}); is it a g2core in JSON mode at ${this.opts.baudRate} baud?`,
      });
      return;
    }
    this.retryMs = this.opts.retryMs ?? 1000;
    this.setState({ state: 'online', since: this.now() });
    this.pump();
  }

  private bannerWaiter: (() => void) | null = null;

  private bannerOrTimeout(gen: number): Promise<void> {
    return new Promise<void>((resolve) => {
      const t = this.st(() => {
        this.bannerWaiter = null;
        resolve();
      }, this.opts.bannerWaitMs ?? 1500);
      this.bannerWaiter = () => {
        this.ct(t);
        this.bannerWaiter = null;
        resolve();
      };
      if (gen !== this.generation) this.bannerWaiter();
    });
  }

  /** After a reset the board starts from its saved settings: the setup is sent again. */
  private async resync(): Promise<void> {
    const gen = this.generation;
    this.setState({ state: 'connecting' });
    try {
      for (const [k, v] of this.opts.setup ?? []) await this.request(k, v, true);
    } catch {
      // Not answered: the port stays open, the next banner or request tells.
    }
    if (gen === this.generation && this.port) {
      this.setState({ state: 'online', since: this.now() });
      this.pump();
    }
  }

  private failOpen(s: LinkState): void {
    this.setState(s);
    this.scheduleRetry();
  }

  private scheduleRetry(): void {
    if (this.stopped || this.retryTimer !== null) return;
    const ms = this.retryMs;
    this.retryMs = Math.min(10_000, this.retryMs * 2);
    this.retryTimer = this.st(() => {
      this.retryTimer = null;
      void this.connect();
    }, ms);
  }

  /** The port went away under us (unplugged, or the OS ended it). */
  private lost(why: string): void {
    this.port = null;
    this.generation++;
    this.drop(`the board went away (${why})`);
    this.setState({
      state: 'unplugged',
      detail: `the board went away (${why}); waiting for it to come back`,
    });
    this.retryMs = this.opts.retryMs ?? 1000;
    this.scheduleRetry();
  }

  /** Fails everything in flight or waiting: never replayed. */
  private drop(why: string, reset = false): void {
    const all = [...this.inFlight, ...this.jsonInFlight, ...this.urgent];
    this.inFlight = [];
    this.jsonInFlight = [];
    this.urgent = [];
    for (const f of all) f.done(new LinkDown(why, reset));
  }

  private onData(chunk: Buffer): void {
    this.rx += chunk.toString('utf8');
    let i: number;
    while ((i = this.rx.search(/[\r\n]/)) >= 0) {
      const line = this.rx.slice(0, i);
      this.rx = this.rx.slice(i + 1);
      if (line.trim() !== '') this.onLine(line);
    }
    // An endless line is noise (or hostile): dropped, not kept.
    if (this.rx.length > MAX_RX_LINE) this.rx = '';
  }

  private onLine(line: string): void {
    this.lastHeard = this.now();
    const m = parseBoardLine(line);
    if (m.type === 'banner') {
      this.banner = scalarsOf(m.info);
      if (this.bannerWaiter) this.bannerWaiter();
      else if (this.online) {
        this.drop('the board reset (new start-up banner)', true);
        for (const l of this.listeners) l.reset?.(m.info);
        void this.resync();
      }
    } else if (m.type === 'response') {
      this.onResponse(m.r, m.status);
    }
    for (const l of this.listeners) l.message?.(m);
    this.pump();
  }

  /**
   * An `{r}`, matched by its content. A JSON answer names its key: it answers the oldest request
   * of that key (a JSON request, or a job's JSON line); it says nothing about the G-code lines
   * waiting in the board, which the firmware answers later. An answer naming no key (or only
   * what a G-code answer echoes) answers the oldest G-code line in flight; with none in flight it
   * is stray (old builds answer `!` with one) and ignored, as is an answer nothing asked for.
   */
  private onResponse(r: JsonObject, status: number): void {
    const keys = Object.keys(r)
      .map((k) => k.toLowerCase())
      .filter((k) => !GCODE_ANSWER_KEYS.has(k));
    if (keys.length > 0) {
      const named = (f: InFlight): boolean => f.key !== null && keys.includes(f.key);
      let lane = this.jsonInFlight;
      let at = lane.findIndex(named);
      if (at < 0) {
        lane = this.inFlight;
        at = lane.findIndex(named);
      }
      // A JSON syntax error answers `{"err":…}` without the key: the oldest JSON request.
      if (at < 0 && keys.length === 1 && keys[0] === 'err' && this.jsonInFlight.length) {
        lane = this.jsonInFlight;
        at = 0;
      }
      if (at < 0) return;
      const [f] = lane.splice(at, 1);
      f?.done({ r, status });
      return;
    }
    // TinyG answers an unknown name without naming it (`{"r":{},"f":[3,100,10]}`, the CNCjs
    // capture): status 100 is a name only JSON has, so it answers the oldest JSON request.
    if (status === 100) {
      const lane = this.jsonInFlight.length ? this.jsonInFlight : this.inFlight;
      const at = lane.findIndex((f) => f.key !== null);
      if (at >= 0) {
        lane.splice(at, 1)[0]?.done({ r, status });
        return;
      }
    }
    const at = this.inFlight.findIndex((f) => f.key === null);
    if (at >= 0) {
      const [f] = this.inFlight.splice(at, 1);
      f?.done({ r, status });
      return;
    }
    // No G-code line in flight: a refusal without a key answers the oldest JSON request; an empty
    // OK answer is stray (old builds answer `!` with one) and ignored.
    if (status !== 0 && this.jsonInFlight.length) this.jsonInFlight.shift()?.done({ r, status });
  }

  /** G-code lines in flight are forgotten (after a flush they never answer): the window opens again. */
  forgetInFlight(why: string): void {
    const gone = this.inFlight.filter((f) => f.key === null);
    this.inFlight = this.inFlight.filter((f) => f.key !== null);
    for (const g of gone) g.done(new LinkDown(why));
    this.pump();
  }

  get linesInFlight(): number {
    return this.inFlight.length;
  }

  private write(data: string): void {
    if (!this.port) throw new LinkDown('the board is not connected');
    // The bytes that reach the board are checked, not the string: printable ASCII lines or one
    // control. Whatever a check before this missed is refused here, and nothing is written.
    const bytes = wireBytes(data);
    if (typeof bytes === 'string') throw new UnsafeBytes(`not written to the board: ${bytes}`);
    this.written.push(data);
    if (this.written.length > 100_000) this.written.splice(0, 50_000);
    this.port.write(bytes);
  }

  /** Sends what fits in each lane: JSON requests (answered at once), then the streamer's lines. */
  pump(): void {
    if (!this.port) return;
    while (this.jsonInFlight.length < JSON_LANE) {
      const next = this.urgent.shift();
      if (!next) break;
      if (!this.send(next, this.jsonInFlight)) return;
    }
    while (this.inFlight.length < this.window) {
      // A job's JSON line is in flight alone: whatever answer comes is its own.
      if (this.inFlight.some((f) => f.json)) return;
      const next = this.pullData();
      if (!next) return;
      if (!this.send(next, this.inFlight)) return;
      this.maxInFlight = Math.max(this.maxInFlight, this.inFlight.length);
    }
  }

  private send(next: InFlight, lane: InFlight[]): boolean {
    lane.push(next);
    try {
      this.write(next.line + '\n');
      return true;
    } catch (e) {
      lane.splice(lane.indexOf(next), 1);
      next.done(e instanceof Error ? e : new Error(String(e)));
      return false;
    }
  }

  private pullData(): InFlight | null {
    if (!this.online) return null;
    const d = this.source?.(this.inFlight.length);
    return d ? { line: d.line, key: jsonKeyOf(d.line), json: d.line.startsWith('{'), done: d.done } : null;
  }

  /**
   * A JSON request (`{"key":value}`), answered by its `{r}`. Fails at once when the board is not
   * connected; never queued for later.
   */
  request(key: string, value: Json, duringSetup = false): Promise<Reply> {
    if (!this.port || (!duringSetup && !this.online)) return Promise.reject(new LinkDown(this.downWords()));
    return new Promise<Reply>((resolve, reject) => {
      const timer = this.st(() => {
        const i = this.urgent.indexOf(entry);
        if (i >= 0) this.urgent.splice(i, 1);
        const j = this.jsonInFlight.indexOf(entry);
        if (j >= 0) this.jsonInFlight.splice(j, 1);
        settle(new LinkDown(`no answer from the board to ${key} within ${this.timeoutMs / 1000} s`));
        this.pump();
      }, this.timeoutMs);
      let settled = false;
      const settle = (r: Reply | Error): void => {
        if (settled) return;
        settled = true;
        this.ct(timer);
        if (r instanceof Error) reject(r);
        else resolve(r);
      };
      const entry: InFlight = {
        line: jsonLine(key, value),
        key: key.toLowerCase(),
        json: true,
        done: settle,
      };
      this.urgent.push(entry);
      this.pump();
    });
  }

  private get timeoutMs(): number {
    return this.opts.requestTimeoutMs ?? 5000;
  }

  /** A single-character control, written at once between lines. Throws when not connected. */
  control(c: (typeof CTRL)[keyof typeof CTRL]): void {
    if (!this.port) throw new LinkDown(this.downWords());
    this.write(c);
  }

  downWords(): string {
    const s = this.current;
    switch (s.state) {
      case 'online':
        return 'online';
      case 'connecting':
        return 'connecting to the board';
      case 'closed':
        return 'the gateway closed the port';
      default:
        return s.detail;
    }
  }
}
