import type { OpenPort } from '../../../fleet/server-part';
import {
  CTRL,
  DEFAULT_WINDOW,
  MAX_RX_LINE,
  jsonLine,
  parseBoardLine,
  scalarsOf,
  type Json,
  type JsonObject,
  wireBytes,
} from './protocol';
import {
  classifyOpenError,
  GCODE_ANSWER_KEYS,
  JSON_LANE,
  jsonKeyOf,
  LinkDown,
  pickBoardPort,
  UnsafeBytes,
  type DataLine,
  type InFlight,
  type LinkListener,
  type LinkOptions,
  type LinkState,
  type Reply,
} from './link-api';

/**
 * The gateway's one connection to a g2core/TinyG board on a serial port (issue 19, protocol-notes
 * `linemode_flow_control`, g2core `xio.cpp`). Two lanes: G-code lines, at most `window` in flight;
 * JSON lines (`{`…), controls answered at once even in a hold, at most `JSON_LANE`. An `{r}` is
 * matched by content: a JSON answer names its key, else (none, `gc`/`n`/`msg`) it answers the
 * oldest G-code line. `!` `~` `%` ^D ^X ENQ go between whole lines. No queueing while closed.
 */

export {
  classifyOpenError,
  JSON_LANE,
  jsonKeyOf,
  LinkDown,
  pickBoardPort,
  UnsafeBytes,
  type DataLine,
  type LinkListener,
  type LinkOptions,
  type LinkState,
  type Reply,
} from './link-api';
/** The port types are every serial part's (src/fleet/server-part.ts). */
export type { OpenPort, PortEvents, PortInfo, PortOpener } from '../../../fleet/server-part';

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
