import configGroups from '../sim/data/config-groups-100.12.json' with { type: 'json' };
import { CTRL, MAX_LINE_BYTES, isObject, type Json, type JsonObject } from './protocol';

/**
 * A SIMULATED g2core (or TinyG) board on the far end of a serial link, speaking the line protocol
 * as the captures in ../shared/fixtures/g2core/ show it: the start-up banner, `{r}` with a footer,
 * filtered status reports every `si` ms while `sv` is on, queue reports when `qv` is on,
 * exception reports, single-character controls acted on as they arrive (`%` only in hold or
 * right after `!`), the 254-byte line limit and the TinyG footer forms. Motion is coarse: each
 * motion line takes `msPerLine` in the planner. Used by the tests, and by `npm run sim` on a
 * pseudo-terminal. Everything here is SIMULATED.
 *
 * As the firmware (g2core `xio.cpp` `_scanBuffer`, `controller.cpp` `_dispatch_control`): a line
 * whose first character is `{` is a control: it is read and answered as soon as it arrives, ahead
 * of the G-code lines waiting in the board, with the planner full and throughout a hold. G-code
 * lines are the queue: read only while the planner has room (a full planner, the normal state of
 * a long job, and a hold leave them waiting, unanswered). The footer is `[1, status, bytes]`,
 * bytes being the line's length + 2 on 101.03 (as the recorded sessions show it), + 1 elsewhere.
 *
 * Quirks it reproduces on request (research notes):
 *  - `legacyBangReply`: an old build answered `!` with an empty `{r}` (feedhold-with-queue-reports-2014);
 *  - `stuckInRun()`: the known firmware state where the board stays in run and reports nothing;
 *  - `firmware: '100.26'`: `hp`/`hv` are numbers; `'101.03'`: strings; `'tinyg'`: 4-element footer;
 *  - an unknown key answers status 100 followed by the `{"err":…}` companion line (101.03 names the key in `r`; TinyG answers an empty `r`, as the CNCjs capture).
 */

export type Firmware = '101.03' | '100.26' | 'tinyg';

export interface BoardSimOptions {
  firmware?: Firmware;
  /** Planner slots: lines accepted before the board stops reading (g2core has ~48, TinyG 28). */
  plannerSize?: number;
  msPerLine?: number;
  legacyBangReply?: boolean;
  /** `js.echo_json_gcode_block`: a G-code line's answer names it (`{"r":{"gc":"G1X1"}}`). */
  echoGcode?: boolean;
  setTimeout?: (fn: () => void, ms: number) => unknown;
  clearTimeout?: (t: unknown) => void;
}

const SR_KEYS = ['line', 'posx', 'posy', 'posz', 'feed', 'vel', 'unit', 'coor', 'dist', 'stat', 'hold'];

type Cfg = Record<string, Record<string, Json>>;

/** g2core's relaxed JSON on input: bare keys, `n` for null, `t`/`f` for true/false. */
export function parseRelaxed(text: string): unknown {
  const strict = text
    .replace(/([{,]\s*)([A-Za-z_][A-Za-z0-9_.]*)\s*:/g, '$1"$2":')
    .replace(/:\s*n\b/g, ':null')
    .replace(/:\s*t\b/g, ':true')
    .replace(/:\s*f\b/g, ':false');
  return JSON.parse(strict);
}

export class BoardSim {
  readonly firmware: Firmware;
  private out: (line: string) => void = () => undefined;
  private rxLine = '';
  private afterBang = false;
  /** Lines received and not yet read into the planner (the board stopped reading). */
  private pending: string[] = [];
  private planner: Array<{ line: number; x: number | null; y: number | null; z: number | null }> = [];
  private cfg: Cfg = structuredClone(configGroups) as Cfg;
  private pos = { x: 0, y: 0, z: 0 };
  private abs = true;
  stat = 1;
  private hold = 0;
  private vel = 0;
  private lineNo = 0;
  private lastSr: Record<string, Json> = {};
  private moveTimer: unknown = null;
  private srTimer: unknown = null;
  private stuck = false;
  /** Hung: reads nothing, answers nothing, reports nothing (only ^X is seen). */
  private hung = false;
  private alive = true;
  /** Most lines ever waiting unread: more than the host's window means the host overfilled. */
  maxPending = 0;
  /** Every line the board read, in order (tests check exact bytes). */
  readonly received: string[] = [];
  readonly controls: string[] = [];
  private readonly o: Required<Omit<BoardSimOptions, 'firmware'>>;

  /** G-code lines received and waiting unread (the planner is full, or the board holds). */
  get waiting(): number {
    return this.pending.length;
  }

  /** Lines in the planner (taken, answered, not yet run). */
  get planned(): number {
    return this.planner.length;
  }

  constructor(opts: BoardSimOptions = {}) {
    this.firmware = opts.firmware ?? '101.03';
    this.o = {
      plannerSize: opts.plannerSize ?? 28,
      msPerLine: opts.msPerLine ?? 50,
      legacyBangReply: opts.legacyBangReply ?? false,
      echoGcode: opts.echoGcode ?? false,
      setTimeout: opts.setTimeout ?? ((fn, ms) => setTimeout(fn, ms)),
      clearTimeout: opts.clearTimeout ?? ((t) => clearTimeout(t as ReturnType<typeof setTimeout>)),
    };
    this.cfg.sys!.sv = 0;
    this.cfg.sys!.qv = 0;
    Object.assign(this.cfg.sys!, this.identity());
  }

  /** Where the board's output lines go (each is written with "\n"). */
  connect(out: (line: string) => void): void {
    this.out = out;
  }

  /**
   * The board powers up (or resets): the banner. `banner: false` is a board already running when
   * the port opens (g2core's native USB does not reset then): no banner is seen.
   */
  boot(banner = true): void {
    this.alive = true;
    if (banner) this.sendBanner();
    this.scheduleSr();
  }

  /** The board is gone (unplugged, so unpowered): no more output, and it starts afresh. */
  powerOff(): void {
    this.alive = false;
    this.clear();
  }

  /** What a reset or a power loss forgets: every queued line and motion, the state. */
  private clear(): void {
    this.stopTimers();
    this.stuck = false;
    this.hung = false;
    this.pending = [];
    this.planner = [];
    this.rxLine = '';
    this.stat = 1;
    this.hold = 0;
    this.vel = 0;
    this.lastSr = {};
  }

  /** The known firmware fault: stays in run and goes silent. */
  stuckInRun(): void {
    this.stuck = true;
    this.stat = 5;
    this.stopTimers();
  }

  /** A board that hangs while idle (or anywhere): no answer, no report, until a reset. */
  hang(): void {
    this.hung = true;
    this.stopTimers();
  }

  /** The hung board comes back by itself (it was busy, not dead). */
  unhang(): void {
    this.hung = false;
    this.scheduleSr();
    this.readLines();
  }

  private stopTimers(): void {
    if (this.moveTimer !== null) this.o.clearTimeout(this.moveTimer);
    if (this.srTimer !== null) this.o.clearTimeout(this.srTimer);
    this.moveTimer = null;
    this.srTimer = null;
  }

  private send(v: JsonObject): void {
    if (this.alive && !this.hung) this.out(JSON.stringify(v));
  }

  private footer(status: number, len: number): number[] {
    return this.firmware === 'tinyg'
      ? [1, status, len, 1000 + ((len * 31 + status) % 9000)]
      : [1, status, len];
  }

  /** The identity of this build, as the banner and the `sys` group show it. */
  private identity(): JsonObject {
    const numbers = this.firmware !== '101.03';
    return {
      fv: this.firmware === 'tinyg' ? 0.97 : 0.99,
      fb: this.firmware === '100.26' ? 100.26 : this.firmware === 'tinyg' ? 440.2 : 101.03,
      fbs: '',
      fbc: 'settings_default.h',
      hp: numbers ? 3 : 'ArduinoDue',
      hv: numbers ? 0 : 'na',
      id: '0084-084a-29c6-8ce',
    };
  }

  private sendBanner(): void {
    this.send({ r: { ...this.identity(), msg: 'SYSTEM READY' }, f: this.footer(0, 1) });
  }

  /** Bytes from the host, as the serial port delivers them. */
  receive(bytes: Buffer | string): void {
    if (!this.alive) return;
    const text = typeof bytes === 'string' ? bytes : bytes.toString('latin1');
    for (const ch of text) {
      if ((this.stuck || this.hung) && ch !== CTRL.reset) continue;
      if (ch === CTRL.feedhold) {
        this.controls.push(ch);
        this.feedhold();
        this.afterBang = true;
        continue;
      }
      if (ch === CTRL.flush && (this.afterBang || this.stat === 6)) {
        this.controls.push(ch);
        this.flush();
        this.afterBang = false;
        continue;
      }
      if (ch === CTRL.cycleStart || ch === CTRL.kill || ch === CTRL.reset || ch === CTRL.enquiry) {
        this.controls.push(ch);
        this.afterBang = false;
        this.singleChar(ch);
        continue;
      }
      if (ch === '\n' || ch === '\r') {
        const line = this.rxLine;
        this.rxLine = '';
        // A JSON line is a control: answered now, ahead of the G-code lines waiting.
        if (line.startsWith('{')) {
          this.received.push(line);
          this.execute(line);
          continue;
        }
        if (line !== '') this.pending.push(line);
        this.maxPending = Math.max(this.maxPending, this.pending.length);
        this.readLines();
        continue;
      }
      this.afterBang = false;
      this.rxLine += ch;
    }
  }

  private singleChar(ch: string): void {
    if (ch === CTRL.enquiry) this.send({ ack: true });
    else if (ch === CTRL.cycleStart && this.stat === 6) {
      this.stat = this.planner.length ? 5 : 3;
      this.hold = 0;
      this.report();
      this.runPlanner();
    } else if (ch === CTRL.kill) {
      this.flush();
      this.send({ er: { fb: 101.03, st: 207, msg: 'Kill job - Job killed by ^d' } });
      this.stat = 5;
      this.report();
      this.stat = 4;
      this.hold = 0;
      this.vel = 0;
      this.abs = true;
      this.report();
    } else if (ch === CTRL.reset) {
      this.clear();
      this.o.setTimeout(() => this.boot(), 100);
    }
  }

  private feedhold(): void {
    if (this.o.legacyBangReply) this.send({ r: {}, f: this.footer(0, 17) });
    if (this.stat !== 5) return;
    this.stat = 6;
    this.hold = 4;
    this.vel = 0;
    if (this.moveTimer !== null) this.o.clearTimeout(this.moveTimer);
    this.moveTimer = null;
    this.report();
  }

  private flush(): void {
    this.pending = [];
    this.planner = [];
    this.rxLine = '';
    if (this.moveTimer !== null) this.o.clearTimeout(this.moveTimer);
    this.moveTimer = null;
    if (this.cfg.sys!.qv) this.send({ qr: this.o.plannerSize });
  }

  /** Reads waiting lines while the planner has room (a full planner stops reading: no `{r}`). */
  private readLines(): void {
    while (this.pending.length && this.planner.length < this.o.plannerSize && !this.stuck && !this.hung) {
      const line = this.pending.shift()!;
      this.received.push(line);
      this.execute(line);
    }
  }

  private execute(line: string): void {
    const size = Buffer.byteLength(line) + 1;
    const len = size + (this.firmware === '101.03' ? 1 : 0);
    if (size >= MAX_LINE_BYTES) {
      this.send({ r: {}, f: this.footer(107, len) });
      return;
    }
    const t = line.trim();
    if (t.startsWith('{')) {
      this.jsonLine(t, len);
      return;
    }
    const status = this.gcode(t);
    this.send({ r: this.o.echoGcode ? { gc: t } : {}, f: this.footer(status, len) });
  }

  private jsonLine(t: string, len: number): void {
    let v: unknown;
    try {
      v = parseRelaxed(t);
    } catch {
      this.send({ r: {}, f: this.footer(108, len) });
      return;
    }
    if (!isObject(v) || Object.keys(v).length !== 1) {
      this.send({ r: {}, f: this.footer(101, len) });
      return;
    }
    const [key, value] = Object.entries(v)[0]!;
    const k = key.toLowerCase();
    if (k === 'gc' && typeof value === 'string') {
      this.send({ r: {}, f: this.footer(this.gcode(value), len) });
      return;
    }
    if (k === 'sr') {
      this.send({ r: { sr: this.srValues() }, f: this.footer(0, len) });
      return;
    }
    if (k === 'clear' || k === 'clr') {
      if (this.stat === 2) this.stat = 3;
      this.send({ r: { [k]: null }, f: this.footer(0, len) });
      this.report();
      return;
    }
    const group = this.cfg[k];
    if (group) {
      if (value === null) this.send({ r: { [k]: group }, f: this.footer(0, len) });
      else if (isObject(value)) {
        Object.assign(group, value);
        this.send({ r: { [k]: group }, f: this.footer(0, len) });
      } else this.send({ r: { [k]: value }, f: this.footer(101, len) });
      return;
    }
    const found = this.findKey(k);
    if (!found) {
      // TinyG does not name the unknown key (the CNCjs capture): `{"r":{},"f":[3,100,10]}`.
      this.send({ r: this.firmware === 'tinyg' ? {} : { [k]: null }, f: this.footer(100, len) });
      if (this.firmware !== '100.26')
        this.send({ err: { code: 100, msg: 'Unrecognized command or config name' } });
      return;
    }
    if (value !== null) {
      if (['fb', 'fv', 'fbs', 'fbc', 'hp', 'hv', 'id'].includes(found.key)) {
        this.send({ r: { [k]: found.g[found.key] ?? null }, f: this.footer(104, len) });
        return;
      }
      found.g[found.key] = value;
      if (k === 'si' || k === 'sv') this.scheduleSr();
    }
    this.send({ r: { [k]: found.g[found.key] ?? null }, f: this.footer(0, len) });
  }

  private findKey(k: string): { g: Record<string, Json>; key: string } | null {
    if (k in this.cfg.sys!) return { g: this.cfg.sys!, key: k };
    for (const name of Object.keys(this.cfg).sort((a, b) => b.length - a.length)) {
      if (k.startsWith(name) && k.length > name.length && k.slice(name.length) in this.cfg[name]!)
        return { g: this.cfg[name]!, key: k.slice(name.length) };
    }
    return null;
  }

  /** A G-code line: motion joins the planner; the status code of the footer is returned. */
  private gcode(t: string): number {
    const code = t.replace(/\(.*?\)|;.*$/g, '').toUpperCase();
    if (this.stat === 2 || this.stat === 12 || this.stat === 13) return 204;
    if (/\bG90\b/.test(code)) this.abs = true;
    if (/\bG91\b/.test(code)) this.abs = false;
    const n = /^N(\d+)/.exec(code);
    const axis = (a: string): number | null => {
      const m = new RegExp(`${a}(-?[0-9.]+)`).exec(code);
      return m ? Number(m[1]) : null;
    };
    if (/\bG0?[0123]\b/.test(code) || /^[XYZ]/.test(code)) {
      const x = axis('X');
      const y = axis('Y');
      const z = axis('Z');
      if ([x, y, z].some((v) => v !== null && !Number.isFinite(v))) return 130;
      this.planner.push({ line: n ? Number(n[1]) : ++this.lineNo, x, y, z });
      if (this.cfg.sys!.qv) this.send({ qr: this.o.plannerSize - this.planner.length });
      if (this.stat !== 6) this.runPlanner();
      return 0;
    }
    if (/\bM0?2\b|\bM30\b/.test(code)) return 0;
    if (/^[GMTSF]/.test(code) || code === '') return 0;
    return 130;
  }

  private runPlanner(): void {
    if (this.moveTimer !== null || this.stat === 6 || this.stuck) return;
    const move = this.planner[0];
    if (!move) {
      if (this.stat === 5) {
        this.stat = 3;
        this.vel = 0;
        this.report();
      }
      return;
    }
    if (this.stat !== 5) {
      this.stat = 5;
      this.vel = 1000;
      this.report();
    }
    this.moveTimer = this.o.setTimeout(() => {
      this.moveTimer = null;
      this.planner.shift();
      const rel = !this.abs;
      if (move.x !== null) this.pos.x = rel ? this.pos.x + move.x : move.x;
      if (move.y !== null) this.pos.y = rel ? this.pos.y + move.y : move.y;
      if (move.z !== null) this.pos.z = rel ? this.pos.z + move.z : move.z;
      this.lineNo = Math.max(this.lineNo, move.line);
      if (this.cfg.sys!.qv) this.send({ qr: this.o.plannerSize - this.planner.length });
      this.readLines();
      this.runPlanner();
    }, this.o.msPerLine);
  }

  private srValues(): Record<string, Json> {
    return {
      line: this.lineNo,
      posx: round(this.pos.x),
      posy: round(this.pos.y),
      posz: round(this.pos.z),
      feed: 0,
      vel: this.vel,
      unit: 1,
      coor: 1,
      dist: this.abs ? 0 : 1,
      stat: this.stat,
      hold: this.hold,
    };
  }

  /** A filtered status report: only what changed since the last one (sv:1). */
  private report(): void {
    if (!this.cfg.sys!.sv || this.stuck) return;
    const now = this.srValues();
    const changed: JsonObject = {};
    for (const k of SR_KEYS) if (now[k] !== this.lastSr[k]) changed[k] = now[k] ?? null;
    this.lastSr = now;
    if (Object.keys(changed).length) this.send({ sr: changed });
  }

  private scheduleSr(): void {
    if (this.srTimer !== null) this.o.clearTimeout(this.srTimer);
    this.srTimer = null;
    const si = Number(this.cfg.sys!.si) || 250;
    if (!this.cfg.sys!.sv || !this.alive) return;
    this.srTimer = this.o.setTimeout(
      () => {
        this.srTimer = null;
        this.report();
        this.scheduleSr();
      },
      Math.max(100, si),
    );
  }
}

function round(v: number): number {
  return Math.round(v * 1000) / 1000;
}
