import {
  jsonResponse,
  splitPath,
  type SimControl,
  type SimOptions,
  type Simulator,
} from '../../../fleet/sim';
import { httpStatusFor, statusText } from '../codes';
import configGroups from './data/config-groups-100.12.json' with { type: 'json' };
import {
  AXES,
  cloneModel,
  interpret,
  newModel,
  round,
  zeroVec,
  type Action,
  type Axis,
  type AxisVec,
  type GError,
  type InterpEnv,
  type Model,
} from './gcode';

/**
 * A simulated g2core behind the console's REST design (see client.ts for the settled open
 * points). The settings tree is the 100.12 "makeblock" dump from the design's examples
 * (sim/data/config-groups-100.12.json). Time passes on a timer: operations run their lines, moves
 * are interpolated at the feed, homing searches for its switch, dwell waits, feedhold stops and
 * cycle start resumes. Everything here is SIMULATED.
 *
 * Deliberate differences from the dump, each stated so nobody mistakes them for firmware facts:
 *  - soft limits are on (`sl:1`; the dump has 0) so the console's 405 path can be seen;
 *  - the machine powers up 150/100/-30 mm away from its switches (unknown to it until homed).
 */

type Group = Record<string, string | number | boolean | null>;
type Scalar = string | number | boolean | null;

const READ_ONLY_SYS = new Set(['fb', 'fbs', 'fbc', 'fv', 'hp', 'hv', 'id']);
const READ_ONLY_HEATER = new Set(['t', 'op', 'tr', 'at', 'an']);
/** Whole groups the firmware refuses to set over JSON: G92 offsets and the G28/G30 positions are set by G-code. */
const READ_ONLY_GROUPS = new Set(['g92', 'g28', 'g30']);
const OVERRIDES = new Set(['mfo', 'mto', 'sso']);
const COMMAND_KEYS = new Set(['clear', 'clr', 'alarm', 'shutd', 'panic']);

/** Default status report fields (settings_default.h) plus machine positions, plane, path, hold and overrides. */
export const SR_FIELDS = [
  'line',
  'posx',
  'posy',
  'posz',
  'posa',
  'mpox',
  'mpoy',
  'mpoz',
  'mpoa',
  'feed',
  'vel',
  'unit',
  'coor',
  'dist',
  'admo',
  'frmo',
  'momo',
  'plan',
  'path',
  'stat',
  'hold',
  'mfo',
  'sso',
];

type Range = { min?: number; max?: number; set?: number[] };

/** Ranges the simulated firmware checks (code 108 below min, 109 above max, 110 not in set). */
const SYS_RANGES: Record<string, Range> = {
  mfo: { min: 0.05, max: 2 },
  mto: { min: 0.05, max: 2 },
  sso: { min: 0.05, max: 2 },
  si: { min: 100, max: 50000 },
  sl: { set: [0, 1] },
  lim: { set: [0, 1] },
  saf: { set: [0, 1] },
  gun: { set: [0, 1] },
  gco: { set: [1, 2, 3, 4, 5, 6] },
  gpl: { set: [0, 1, 2] },
  gpa: { set: [0, 1, 2] },
  gdi: { set: [0, 1] },
  jv: { set: [0, 1, 2, 3, 4, 5, 6, 7, 8] },
  sv: { set: [0, 1, 2] },
  qv: { set: [0, 1, 2] },
};
const AXIS_RANGES: Record<string, Range> = {
  am: { set: [0, 1, 2, 3] },
  vm: { min: 0.001 },
  fr: { min: 0.001 },
  jm: { min: 0.001 },
  jh: { min: 0.001 },
  hi: { set: [0, 1, 2, 3, 4, 5, 6, 7, 8, 9] },
  hd: { set: [0, 1] },
  sv: { min: 0 },
  lv: { min: 0 },
};
const MOTOR_RANGES: Record<string, Range> = {
  ma: { set: [0, 1, 2, 3, 4, 5] },
  sa: { min: 0.001, max: 360 },
  tr: { min: 0.0001 },
  mi: { set: [1, 2, 4, 8, 16, 32, 64, 128, 256] },
  po: { set: [0, 1] },
  pm: { set: [0, 1, 2, 3] },
  pl: { min: 0, max: 1 },
};

class G2Fail extends Error {
  constructor(
    readonly code: number,
    readonly additional = '',
  ) {
    super(statusText(code));
  }
}

function errorResponse(code: number, additional = ''): Response {
  return jsonResponse(
    { status: { code, description: statusText(code), additional_description: additional } },
    httpStatusFor(code),
  );
}

interface Op {
  id: number;
  optype: 'run' | 'sendfile';
  value: string[] | string;
  lines: string[];
  /** Next line to interpret. */
  next: number;
  /** Lines finished. */
  done: number;
  state: 'pend' | 'run' | 'done' | 'error';
  error: { code: number; description: string; additional_description: string } | null;
  jobId: number | null;
  /** Replies of the operation's JSON lines, in order (`{"xvm":40000}`). */
  replies: Record<string, unknown>[];
}

interface SimJob {
  id: number;
  name: string;
  lines: string[];
  state: 'queued' | 'running' | 'paused' | 'done' | 'killed' | 'error';
  started: number | null;
  finished: number | null;
  operation: number | null;
}

/**
 * One leg of a homing cycle, per axis in the firmware's order (Z, X, Y, A, B, C): `search`
 * toward the switch at the search velocity (sv), `latch` off the switch at the latch velocity
 * (lv, until it opens: at most lb, 1 mm here), `backoff` the zero backoff (zb) at sv. After the
 * last leg the axis is at its home position (tn, or tm with hd=1) and homed.
 */
interface HomeLeg {
  t: 'homeleg';
  axis: Axis;
  phase: 'search' | 'latch' | 'backoff';
  /** Believed position of the axis at the end of the leg. */
  to: number;
  /** mm/min. */
  rate: number;
  /** Home position, set when the last leg ends. */
  home: number | null;
}

type SimAction = Action | HomeLeg;

interface Running {
  action: SimAction;
  elapsed: number;
  from: AxisVec;
  /** Homing: the planned end position. */
  to: AxisVec;
  ms: number;
  rate: number;
}

const MAX_JOB_BYTES = 4 * 1024 * 1024;
/** Longest line the simulated firmware accepts (a simulator choice: g2core reads lines into a ~255-byte buffer). */
const MAX_LINE = 254;

export const DEMO_JOB_NAME = 'demo-pocket.nc';
/** Between two demo runs: the simulated operator changes the stock. */
export const DEMO_PAUSE_MS = 15_000;

/**
 * The demo job: home (Z first, as the design's own example), then a 100 x 80 mm pocket cut in
 * three 1.5 mm steps with 4 mm zig-zag rows at 1500 mm/min: about 4.5 minutes and 150 lines, all
 * inside the 100.12 travel (X/Y 0..420, Z -95..0) with soft limits on.
 */
export function demoPocket(): string[] {
  const lines = ['G21 G90 G17 G94 G54', 'G28.2 Z0', 'G28.2 X0 Y0', 'M3 S12000', 'G4 P2', 'G0 Z-10'];
  for (const depth of [-21.5, -23, -24.5]) {
    lines.push('G0 X100 Y100', `G1 Z${depth} F300`, 'F1500');
    for (let i = 0, y = 100; y <= 180; i++, y += 4) {
      if (y > 100) lines.push(`G1 Y${y}`);
      lines.push(`G1 X${i % 2 === 0 ? 200 : 100}`);
    }
    lines.push('G0 Z-10');
  }
  lines.push('G0 Z-5', 'G0 X10 Y10', 'M5', 'M30');
  return lines;
}

function isRecord(v: unknown): v is Record<string, unknown> {
  return typeof v === 'object' && v !== null && !Array.isArray(v);
}

export class G2coreSimulator implements Simulator {
  readonly kind = 'g2core' as const;
  readonly cfg: Record<string, Group>;
  private readonly now: () => number;
  private readonly timer: ReturnType<typeof setInterval>;
  private last: number;
  /** Planner model: position and modal state after everything executed so far. */
  model: Model = newModel();
  /** Machine position as the controller believes it (mm). */
  mpos: AxisVec = zeroVec();
  /** Physical position minus believed position: unknown until homed. */
  private drift: AxisVec = { x: 150, y: 100, z: -30, a: 0, b: 0, c: 0 };
  stat = 1;
  hold = 0;
  vel = 0;
  line = 0;
  private ended = false;
  private ops = new Map<number, Op>();
  private opSeq = 41;
  private jobs = new Map<number, SimJob>();
  private queue: number[] = [];
  private jobSeq = 0;
  private running: Running | null = null;
  private pending: SimAction[] = [];
  private ticking = false;

  constructor(private readonly opts: SimOptions) {
    this.now = opts.now ?? Date.now;
    this.cfg = structuredClone(configGroups) as Record<string, Group>;
    this.cfg.sys!.sl = 1;
    this.last = this.now();
    this.timer = setInterval(() => this.tick(), opts.tickMs ?? 50);
  }

  dispose(): void {
    clearInterval(this.timer);
  }

  // ------------------------------------------------------------------------------ world

  private num(group: string, key: string): number {
    const v = this.cfg[group]?.[key];
    return typeof v === 'number' ? v : typeof v === 'boolean' ? (v ? 1 : 0) : Number(v ?? 0) || 0;
  }

  private offsetOf(group: string): AxisVec {
    const g = this.cfg[group] ?? {};
    const v = zeroVec();
    for (const a of AXES) v[a] = typeof g[a] === 'number' ? (g[a] as number) : 0;
    return v;
  }

  private env(dry: boolean): InterpEnv {
    const offsets = new Map<string, AxisVec>();
    return {
      axis: (a) => ({
        am: this.num(a, 'am'),
        vm: this.num(a, 'vm'),
        fr: this.num(a, 'fr'),
        tn: this.num(a, 'tn'),
        tm: this.num(a, 'tm'),
        hi: this.num(a, 'hi'),
        hd: this.num(a, 'hd'),
        sv: this.num(a, 'sv'),
        lv: this.num(a, 'lv'),
      }),
      softLimits: this.num('sys', 'sl') === 1,
      feedOverride: this.num('sys', 'mfoe') === 1 ? this.num('sys', 'mfo') || 1 : 1,
      offset: (g) => offsets.get(g) ?? this.offsetOf(g),
      setOffset: (g, v) => {
        const next = { ...(offsets.get(g) ?? this.offsetOf(g)), ...v };
        if (dry) offsets.set(g, next);
        else for (const a of AXES) this.cfg[g]![a] = round(next[a], 4);
      },
      probeConfigured: Object.entries(this.cfg).some(([k, g]) => k.startsWith('di') && g.fn === 4),
      checkJson: (k, v) => {
        try {
          if (v !== null) this.validateSet(k, v, true);
          else this.resolve(k);
          return null;
        } catch (e) {
          return e instanceof G2Fail
            ? { code: e.code, additional: e.additional }
            : { code: 101, additional: k };
        }
      },
    };
  }

  private busy(): boolean {
    return [5, 6, 7, 9, 10].includes(this.stat);
  }

  private alarmed(): number | null {
    if (this.stat === 2) return 204;
    if (this.stat === 12) return 205;
    if (this.stat === 13) return 206;
    return null;
  }

  private currentOp(): Op | null {
    for (const op of this.ops.values()) if (op.state === 'run' || op.state === 'pend') return op;
    return null;
  }

  tick(): void {
    const t = this.now();
    let budget = Math.max(0, t - this.last);
    this.last = t;
    if (this.demo && !this.ticking) {
      this.ticking = true;
      try {
        this.demoStep();
      } finally {
        this.ticking = false;
      }
    }
    if (this.alarmed() !== null || this.stat === 6 || this.stat === 11) {
      this.vel = 0;
      return;
    }
    let guard = 0;
    while (guard++ < 2000) {
      if (!this.running) {
        const action = this.pending.shift();
        if (action) {
          this.begin(action);
          continue;
        }
        const op = this.currentOp();
        if (!op) {
          if (this.busy()) this.stat = this.ended ? 4 : 3;
          this.vel = 0;
          return;
        }
        this.step(op);
        continue;
      }
      if (budget <= 0) return;
      const r = this.running;
      const use = Math.min(budget, r.ms - r.elapsed);
      budget -= use;
      r.elapsed += use;
      const f = r.ms > 0 ? Math.min(1, r.elapsed / r.ms) : 1;
      if (r.action.t === 'move' || r.action.t === 'homeleg') {
        for (const a of AXES) this.mpos[a] = r.from[a] + (r.to[a] - r.from[a]) * f;
        this.vel = r.rate;
      } else this.vel = 0;
      if (r.elapsed >= r.ms) this.finish(r);
    }
  }

  /** Interpret the next line of the running operation. */
  private step(op: Op): void {
    if (op.state === 'pend') {
      op.state = 'run';
      const job = op.jobId !== null ? this.jobs.get(op.jobId) : undefined;
      if (job) {
        job.state = 'running';
        job.started = this.now();
      }
    }
    if (op.next >= op.lines.length) {
      this.finishOp(op, null);
      return;
    }
    const text = op.lines[op.next]!;
    op.next++;
    const r = interpret(this.model, this.env(false), text);
    if ('error' in r) {
      this.finishOp(op, r.error);
      // Soft limits in a running program alarm the machine, as the firmware does.
      if (r.error.code >= 220 && r.error.code <= 233) this.stat = 2;
      return;
    }
    this.model = r.model;
    this.line = r.model.lineNo ?? this.line + 1;
    if (r.actions.length === 0) {
      op.done++;
      if (this.stat !== 9 && this.stat !== 6) this.stat = 5;
      return;
    }
    this.pending.push(...r.actions, { t: 'dwell', ms: -1 } /* marks the end of the line */);
  }

  private begin(action: SimAction): void {
    const op = this.currentOp();
    if (action.t === 'dwell' && action.ms < 0) {
      if (op) op.done++;
      return;
    }
    const from = { ...this.mpos };
    if (action.t === 'move') {
      this.stat = 5;
      this.running = {
        action,
        elapsed: 0,
        from,
        to: action.to,
        ms: action.ms,
        rate: action.rate / this.unitScale(),
      };
    } else if (action.t === 'dwell') {
      this.stat = 5;
      this.running = { action, elapsed: 0, from, to: from, ms: action.ms, rate: 0 };
    } else if (action.t === 'home') {
      this.stat = 9;
      this.pending.unshift(...this.homeLegs(action.axes));
    } else if (action.t === 'homeleg') {
      this.stat = 9;
      const to = { ...from, [action.axis]: action.to };
      const ms = (Math.abs(action.to - from[action.axis]) / Math.max(1, action.rate)) * 60_000;
      this.running = { action, elapsed: 0, from, to, ms, rate: action.rate };
    } else if (action.t === 'end') {
      this.ended = true;
    } else if (action.t === 'json') {
      // Like the firmware's {"r":{…}}: null reads, a value sets and echoes what is now set.
      const reply: Record<string, unknown> = {};
      for (const [k, v] of Object.entries(action.values)) {
        try {
          if (v !== null) this.applySet(k, v);
          reply[k] = this.readValue(k);
        } catch {
          reply[k] = null;
        }
      }
      if (op) op.replies.push(reply);
    }
  }

  private finish(r: Running): void {
    this.running = null;
    this.vel = 0;
    if (r.action.t === 'homeleg' && r.action.home !== null) {
      const a = r.action.axis;
      this.mpos[a] = r.action.home;
      this.model.pos[a] = r.action.home;
      this.drift[a] = 0;
      if (!this.pending.some((p) => p.t === 'homeleg')) this.stat = 5;
    }
  }

  /**
   * The legs of a homing cycle. The switch sits zb + 1 mm beyond the home position, so that after
   * search, latch and zero backoff the axis stands exactly at home. Until then the simulator
   * knows where the axis physically is (position + drift); the controller does not.
   */
  private homeLegs(axes: Axis[]): HomeLeg[] {
    const legs: HomeLeg[] = [];
    const pos = { ...this.mpos };
    for (const a of axes) {
      const toMax = this.num(a, 'hd') === 1;
      const dir = toMax ? 1 : -1;
      const home = toMax ? this.num(a, 'tm') : this.num(a, 'tn');
      const latch = Math.min(1, Math.max(0.1, this.num(a, 'lb') || 1));
      const zb = Math.max(0, this.num(a, 'zb'));
      const sv = Math.max(1, this.num(a, 'sv'));
      const lv = Math.max(1, this.num(a, 'lv'));
      const switchAt = home + dir * (zb + latch); // physical
      const atSwitch = pos[a] + (switchAt - (pos[a] + this.drift[a]));
      legs.push(
        { t: 'homeleg', axis: a, phase: 'search', to: atSwitch, rate: sv, home: null },
        { t: 'homeleg', axis: a, phase: 'latch', to: atSwitch - dir * latch, rate: lv, home: null },
        { t: 'homeleg', axis: a, phase: 'backoff', to: atSwitch - dir * (latch + zb), rate: sv, home },
      );
      pos[a] = home;
    }
    return legs;
  }

  private finishOp(op: Op, err: GError | null): void {
    op.state = err ? 'error' : 'done';
    op.error = err
      ? { code: err.code, description: statusText(err.code), additional_description: err.additional }
      : null;
    this.pending = [];
    this.running = null;
    const job = op.jobId !== null ? this.jobs.get(op.jobId) : undefined;
    if (job && (job.state === 'running' || job.state === 'paused' || job.state === 'queued')) {
      job.state = err ? (err.code === 207 ? 'killed' : 'error') : 'done';
      job.finished = this.now();
    }
    if (!this.currentOp() && this.busy()) this.stat = this.ended ? 4 : 3;
    this.vel = 0;
    this.ended = false;
  }

  /**
   * Kill. On the operation in motion it is the firmware's queue flush + job kill (^D): motion
   * stops where it is, the planner forgets it and every operation queued behind it (a stop must
   * stop everything), the machine ends in stat 4 (End) as the 101.03 capture shows. On an
   * operation still pending it only removes that operation.
   */
  private kill(op: Op, code = 207, additional = 'Job killed'): void {
    const wasRunning = op.state === 'run';
    if (wasRunning) {
      this.running = null;
      this.pending = [];
      // ^D "behaves like M30": program-end resets (G90, G94, G1, spindle off).
      this.model = {
        ...cloneModel(this.model),
        pos: { ...this.mpos },
        dist: 0,
        frmo: 1,
        momo: 1,
        spindle: 0,
      };
      this.hold = 0;
      this.finishOp(op, { code, additional });
      for (const o of this.ops.values()) {
        if (o.state === 'pend') this.finishOp(o, { code, additional: `flushed with operation ${op.id}` });
      }
      this.stat = 4;
      return;
    }
    this.finishOp(op, { code, additional });
  }

  private unitScale(): number {
    return this.model.unit === 0 ? 25.4 : 1;
  }

  /** Every status value the simulated firmware can report. */
  status(): Record<string, Scalar> {
    const s = this.unitScale();
    const co = this.offsetOf(`g${53 + this.model.coor}`);
    const g92 = this.offsetOf('g92');
    const out: Record<string, Scalar> = {
      line: this.line,
      feed: round(this.model.frmo === 0 ? this.model.feed : this.model.feed / s, 3),
      vel: round(this.vel, 2),
      unit: this.model.unit,
      coor: this.model.coor,
      dist: this.model.dist,
      admo: this.model.admo,
      frmo: this.model.frmo,
      momo: this.model.momo,
      plan: this.model.plan,
      path: this.model.path,
      stat: this.stat,
      hold: this.hold,
      mfo: this.num('sys', 'mfo'),
      mto: this.num('sys', 'mto'),
      sso: this.num('sys', 'sso'),
    };
    for (const a of AXES) {
      const linear = a === 'x' || a === 'y' || a === 'z';
      out[`pos${a}`] = round((this.mpos[a] - co[a] - g92[a]) / (linear ? s : 1));
      out[`mpo${a}`] = round(this.mpos[a] / (linear ? s : 1));
      out[`hom${a}`] = this.model.homed[a] ? 1 : 0;
    }
    out.home = AXES.filter((a) => this.num(a, 'am') !== 0).every((a) => this.model.homed[a]) ? 1 : 0;
    return out;
  }

  // ------------------------------------------------------------------------------ keys

  /** Resolves a key in any of its forms: group, group/key, group.key, groupkey, system key, status key. */
  resolve(
    rawKey: string,
  ):
    | { kind: 'group'; group: string }
    | { kind: 'key'; group: string; key: string }
    | { kind: 'status'; key: string }
    | { kind: 'pos'; prefix: 'pos' | 'mpo' }
    | { kind: 'command'; key: string } {
    const k = rawKey.trim().toLowerCase();
    const sep = /[/.]/.exec(k);
    if (sep) {
      const group = k.slice(0, sep.index);
      const key = k.slice(sep.index + 1);
      const g = this.cfg[group];
      if (g && key in g) return { kind: 'key', group, key };
      if ((group === 'pos' || group === 'mpo') && (AXES as readonly string[]).includes(key)) {
        return { kind: 'status', key: `${group}${key}` };
      }
      throw new G2Fail(100, rawKey);
    }
    if (k in this.cfg) return { kind: 'group', group: k };
    if (COMMAND_KEYS.has(k)) return { kind: 'command', key: k };
    if (k === 'pos' || k === 'mpo') return { kind: 'pos', prefix: k };
    if (this.cfg.sys && k in this.cfg.sys) return { kind: 'key', group: 'sys', key: k };
    if (k in this.status()) return { kind: 'status', key: k };
    const groups = Object.keys(this.cfg).sort((a, b) => b.length - a.length);
    for (const g of groups) {
      if (k.startsWith(g) && k.length > g.length && k.slice(g.length) in this.cfg[g]!) {
        return { kind: 'key', group: g, key: k.slice(g.length) };
      }
    }
    throw new G2Fail(100, rawKey);
  }

  private readValue(rawKey: string): unknown {
    const r = this.resolve(rawKey);
    switch (r.kind) {
      case 'group':
        return { ...this.cfg[r.group] };
      case 'key':
        return this.cfg[r.group]![r.key];
      case 'status':
        return this.status()[r.key];
      case 'pos': {
        const st = this.status();
        return Object.fromEntries(AXES.map((a) => [a, st[`${r.prefix}${a}`]]));
      }
      case 'command':
        throw new G2Fail(105, rawKey);
    }
  }

  /** Checks a set; with `dryRun` nothing changes. Throws G2Fail. */
  private validateSet(rawKey: string, value: unknown, dryRun: boolean): void {
    const r = this.resolve(rawKey);
    if (r.kind === 'status' || r.kind === 'pos') throw new G2Fail(104, `${rawKey} is a status value`);
    if (r.kind === 'command') throw new G2Fail(106, rawKey);
    if (r.kind === 'group') {
      if (!isRecord(value)) throw new G2Fail(116, `${rawKey} is a group: send an object`);
      for (const [k, v] of Object.entries(value)) {
        if (!(k in this.cfg[r.group]!)) throw new G2Fail(100, `${r.group}${k}`);
        this.validateKey(r.group, k, v);
      }
    } else this.validateKey(r.group, r.key, value);
    if (!dryRun) this.applySet(rawKey, value);
  }

  private validateKey(group: string, key: string, value: unknown): void {
    if (READ_ONLY_GROUPS.has(group)) throw new G2Fail(104, `${group}${key}`);
    if (group === 'sys' && READ_ONLY_SYS.has(key)) throw new G2Fail(104, key);
    if (group.startsWith('he') && READ_ONLY_HEATER.has(key)) throw new G2Fail(104, `${group}${key}`);
    if (this.busy() && !(group === 'sys' && OVERRIDES.has(key))) {
      throw new G2Fail(106, 'settings cannot change while the machine is moving');
    }
    const current = this.cfg[group]![key];
    if (typeof current === 'boolean') {
      if (typeof value !== 'boolean' && value !== 0 && value !== 1)
        throw new G2Fail(116, `${group}${key} is true/false`);
      return;
    }
    if (typeof current === 'string') {
      if (typeof value !== 'string') throw new G2Fail(116, `${group}${key} is text`);
      return;
    }
    if (typeof value !== 'number' || !Number.isFinite(value))
      throw new G2Fail(116, `${group}${key} is a number`);
    const table =
      group === 'sys'
        ? SYS_RANGES
        : /^[xyzabc]$/.test(group)
          ? AXIS_RANGES
          : /^\d$/.test(group)
            ? MOTOR_RANGES
            : {};
    const range = table[key];
    if (range) {
      if (range.set && !range.set.includes(value))
        throw new G2Fail(110, `${group}${key} must be one of ${range.set.join(', ')}`);
      if (range.min !== undefined && value < range.min)
        throw new G2Fail(108, `${group}${key} ≥ ${range.min}`);
      if (range.max !== undefined && value > range.max)
        throw new G2Fail(109, `${group}${key} ≤ ${range.max}`);
    }
  }

  private applySet(rawKey: string, value: unknown): void {
    const r = this.resolve(rawKey);
    const set = (group: string, key: string, v: unknown) => {
      const g = this.cfg[group]!;
      g[key] = typeof g[key] === 'boolean' ? v === true || v === 1 : (v as Scalar);
      if (/^\d$/.test(group) && (key === 'sa' || key === 'tr' || key === 'mi')) {
        g.su = round((360 / this.num(group, 'sa')) * (this.num(group, 'mi') / this.num(group, 'tr')), 5);
      }
    };
    if (r.kind === 'group' && isRecord(value)) for (const [k, v] of Object.entries(value)) set(r.group, k, v);
    else if (r.kind === 'key') set(r.group, r.key, value);
  }

  /** Evaluates a filter: null selects, a non-null value returns the key only when it differs. */
  private select(spec: Record<string, unknown>, source: 'machine' | 'status'): Record<string, unknown> {
    const out: Record<string, unknown> = {};
    for (const [k, want] of Object.entries(spec)) {
      if (source === 'status') {
        const st = this.status();
        if (!(k in st)) throw new G2Fail(100, `${k} is not a status report key`);
        if (want === null || want !== st[k]) out[k] = st[k];
        continue;
      }
      const r = this.resolve(k);
      if (r.kind === 'group' && isRecord(want)) {
        const g = this.cfg[r.group]!;
        const part: Record<string, unknown> = {};
        for (const [kk, w] of Object.entries(want)) {
          if (!(kk in g)) throw new G2Fail(100, `${k}${kk}`);
          if (w === null || w !== g[kk]) part[kk] = g[kk];
        }
        if (Object.keys(part).length > 0) out[k] = part;
        continue;
      }
      const v = this.readValue(k);
      if (want === null || JSON.stringify(want) !== JSON.stringify(v)) out[k] = v;
    }
    return out;
  }

  // ------------------------------------------------------------------------------ HTTP

  async fetch(req: Request, rawPath: string): Promise<Response> {
    const { pathname, query } = splitPath(rawPath);
    const path = decodeURIComponent(pathname).replace(/\/+$/, '') || '/';
    const method = req.method.toUpperCase();
    try {
      this.tick();
      if (path === '/version' && method === 'GET') return jsonResponse(this.version());
      if (path === '/status_report' && method === 'GET') return this.getStatus(query);
      if (path === '/machine' && method === 'GET') return this.getMachine(query);
      const key = /^\/machine\/(.+)$/.exec(path)?.[1];
      if (key !== undefined && method === 'GET') return this.getKey(key);
      if (key !== undefined && method === 'PUT') return this.putKey(key, await this.body(req));
      if (path === '/operation' && method === 'POST') return this.postOperation(await this.body(req));
      if (path === '/operation' && method === 'GET') return jsonResponse(this.opList());
      const opId = /^\/operation\/([^/]+)$/.exec(path)?.[1];
      if (opId !== undefined && method === 'GET') return jsonResponse(this.opView(this.findOp(opId)));
      if (opId !== undefined && method === 'PUT')
        return this.putOperation(this.findOp(opId), await this.body(req));
      if (path === '/job' && method === 'POST') return await this.postJob(req);
      if (path === '/job' && method === 'GET') return jsonResponse(this.jobList());
      const jobId = /^\/job\/([^/]+)$/.exec(path)?.[1];
      if (jobId !== undefined && method === 'GET') return jsonResponse(this.jobView(this.findJob(jobId)));
      if (jobId !== undefined && method === 'PUT')
        return this.putJob(this.findJob(jobId), await this.body(req));
      if (jobId !== undefined && method === 'DELETE') return this.deleteJob(this.findJob(jobId));
      if (
        ['/version', '/status_report', '/machine', '/operation', '/job'].includes(path) ||
        key ||
        opId ||
        jobId
      ) {
        return errorResponse(106, `${method} is not supported on ${path}`);
      }
      return errorResponse(100, path);
    } catch (e) {
      if (e instanceof G2Fail) return errorResponse(e.code, e.additional);
      throw e;
    }
  }

  private async body(req: Request): Promise<unknown> {
    const text = await req.text();
    if (text.trim() === '') throw new G2Fail(101, 'a JSON body is required');
    try {
      return JSON.parse(text) as unknown;
    } catch {
      throw new G2Fail(111, text.slice(0, 60));
    }
  }

  private parseFilter(query: URLSearchParams): Record<string, unknown> | null {
    const f = query.get('filter');
    if (f === null) return null;
    let spec: unknown;
    try {
      spec = JSON.parse(f);
    } catch {
      throw new G2Fail(111, `filter: ${f.slice(0, 60)}`);
    }
    if (!isRecord(spec)) throw new G2Fail(101, 'filter must be a JSON object');
    return spec;
  }

  version(): Record<string, Scalar> {
    const s = this.cfg.sys!;
    return {
      fv: s.fv!,
      fb: s.fb!,
      fbs: s.fbs!,
      fbc: s.fbc!,
      hp: s.hp!,
      hv: s.hv!,
      id: s.id!,
      msg: 'SYSTEM READY',
    };
  }

  private getStatus(query: URLSearchParams): Response {
    const spec = this.parseFilter(query);
    if (!spec) {
      const st = this.status();
      return jsonResponse(Object.fromEntries(SR_FIELDS.map((k) => [k, st[k]])));
    }
    return jsonResponse(this.select(spec, 'status'));
  }

  private getMachine(query: URLSearchParams): Response {
    if (query.get('shallow') === 'true') {
      return jsonResponse({ value: Object.fromEntries(Object.keys(this.cfg).map((k) => [k, true])) });
    }
    const spec = this.parseFilter(query);
    if (!spec || Object.keys(spec).length === 0) return jsonResponse({ value: structuredClone(this.cfg) });
    return jsonResponse({ value: this.select(spec, 'machine') });
  }

  private getKey(key: string): Response {
    const k = key.toLowerCase();
    if (COMMAND_KEYS.has(k)) return this.command(k);
    return jsonResponse({ value: this.readValue(key) });
  }

  private command(k: string): Response {
    if (k === 'clear' || k === 'clr') {
      if (this.stat === 13) throw new G2Fail(206, 'PANIC needs a hard reset (^X) or a power cycle');
      if (this.stat === 2 || this.stat === 12) {
        this.stat = 3;
        this.hold = 0;
      }
      return jsonResponse({ value: null });
    }
    if (k === 'alarm') this.raise(2, 18, 'alarm requested');
    if (k === 'shutd') this.raise(12, 5, 'shutdown requested');
    if (k === 'panic') this.raise(13, 6, 'panic requested');
    return jsonResponse({ value: null });
  }

  /** Alarm, shutdown or panic: motion stops, every operation fails with `code`. */
  raise(stat: number, code: number, why: string): void {
    for (const op of this.ops.values())
      if (op.state === 'run' || op.state === 'pend') this.kill(op, code, why);
    this.running = null;
    this.pending = [];
    this.model = { ...cloneModel(this.model), pos: { ...this.mpos } };
    this.stat = stat;
    this.vel = 0;
  }

  private putKey(key: string, value: unknown): Response {
    this.validateSet(key, value, false);
    const r = this.resolve(key);
    if (r.kind === 'group') return jsonResponse({ value: { [key]: { ...this.cfg[r.group] } } });
    return jsonResponse({ value: this.readValue(key) });
  }

  private postOperation(body: unknown): Response {
    if (!isRecord(body)) throw new G2Fail(101, 'expected {"optype":…,"value":…}');
    const { optype, value } = body;
    const rejected = this.alarmed();
    if (rejected !== null) throw new G2Fail(rejected, 'clear the alarm first');
    let lines: string[];
    if (optype === 'run') {
      if (typeof value === 'string') lines = value.split(/\r?\n/);
      else if (Array.isArray(value) && value.every((l) => typeof l === 'string')) lines = value as string[];
      else throw new G2Fail(101, 'value must be a string or an array of lines');
      lines = lines.map((l) => l.trim()).filter((l) => l !== '');
      if (lines.length === 0) throw new G2Fail(101, 'no lines to run');
      // A line longer than the firmware's line buffer is status 107 (HTTP 413 in the design's table).
      const long = lines.findIndex((l) => l.length > MAX_LINE);
      if (long >= 0)
        throw new G2Fail(107, `line ${long + 1} has ${lines[long]!.length} characters > ${MAX_LINE}`);
    } else if (optype === 'sendfile') {
      // The same as PUT /job/{id} {"state":"run"}: one job at a time, never behind other motion.
      const job = this.findJob(String(value));
      if (job.state !== 'queued') throw new G2Fail(106, `job ${job.id} is ${job.state}`);
      if (this.currentOp()) throw new G2Fail(106, 'the machine is busy with another operation');
      this.startJob(job);
      return jsonResponse(job.operation, 201);
    } else throw new G2Fail(101, `unknown optype ${JSON.stringify(optype)}`);
    this.dryRun(lines);
    const op = this.addOp('run', value as string[] | string, lines, null);
    return jsonResponse(op.id, 201);
  }

  /** Validates lines against the model as it will be after everything already queued. */
  private dryRun(lines: string[]): void {
    const env = this.env(true);
    let m = cloneModel(this.model);
    for (const op of this.ops.values()) {
      if (op.state !== 'run' && op.state !== 'pend') continue;
      for (const l of op.lines.slice(op.next)) {
        const r = interpret(m, env, l);
        if (!('error' in r)) m = r.model;
      }
    }
    for (const l of lines) {
      const r = interpret(m, env, l);
      if ('error' in r) throw new G2Fail(r.error.code, `${l}: ${r.error.additional}`);
      m = r.model;
    }
  }

  private addOp(
    optype: 'run' | 'sendfile',
    value: string[] | string,
    lines: string[],
    jobId: number | null,
  ): Op {
    const op: Op = {
      id: ++this.opSeq,
      optype,
      value,
      lines,
      next: 0,
      done: 0,
      state: 'pend',
      error: null,
      jobId,
      replies: [],
    };
    this.ops.set(op.id, op);
    if (this.ops.size > 200) {
      for (const [id, o] of this.ops) {
        if (this.ops.size <= 200) break;
        if (o.state === 'done' || o.state === 'error') this.ops.delete(id);
      }
    }
    this.tick();
    return op;
  }

  private findOp(id: string): Op {
    const op = this.ops.get(Number(id));
    if (!op) throw new G2Fail(100, `no operation ${id}`);
    return op;
  }

  private opView(op: Op): Record<string, unknown> {
    const held = op.state === 'run' && (this.stat === 6 || this.stat === 11);
    const v: Record<string, unknown> = {
      id: op.id,
      optype: op.optype,
      opstate: held ? 'pause' : op.state,
      value: op.value,
      line: op.done,
    };
    if (op.error) v.error = op.error;
    if (op.replies.length > 0) v.r = op.replies;
    return v;
  }

  /** GET /operation: unfinished operations in the order they run, then the 20 latest finished. */
  private opList(): Record<string, unknown>[] {
    const all = [...this.ops.values()];
    const active = all.filter((o) => o.state === 'run' || o.state === 'pend');
    const ended = all
      .filter((o) => !active.includes(o))
      .reverse()
      .slice(0, 20);
    return [...active, ...ended].map((o) => this.opView(o));
  }

  private putOperation(op: Op, body: unknown): Response {
    const want = isRecord(body) ? body.opstate : undefined;
    const active = op.state === 'run' || op.state === 'pend';
    if (want === 'kill') {
      if (!active) throw new G2Fail(106, `operation ${op.id} is ${op.state}`);
      this.kill(op);
    } else if (want === 'pause') {
      if (op.state !== 'run' || this.stat === 6) throw new G2Fail(106, `operation ${op.id} is not moving`);
      this.stat = 6;
      this.hold = 4;
      this.vel = 0;
      this.setJobState(op, 'paused');
    } else if (want === 'run') {
      if (op.state !== 'run' || this.stat !== 6) throw new G2Fail(106, `operation ${op.id} is not held`);
      this.stat = this.running?.action.t === 'homeleg' ? 9 : 5;
      this.hold = 0;
      this.last = this.now();
      this.setJobState(op, 'running');
    } else throw new G2Fail(101, 'opstate must be "pause", "run" or "kill"');
    return jsonResponse(this.opView(op));
  }

  private setJobState(op: Op, state: SimJob['state']): void {
    const job = op.jobId !== null ? this.jobs.get(op.jobId) : undefined;
    if (job) job.state = state;
  }

  // ------------------------------------------------------------------------------ jobs

  private async postJob(req: Request): Promise<Response> {
    const type = req.headers.get('content-type') ?? '';
    let name = '';
    let text = '';
    if (type.includes('multipart/form-data')) {
      const form = await req.formData();
      const file = form.get('file');
      if (!file || typeof file === 'string') throw new G2Fail(101, 'multipart needs a "file" field');
      name = String(form.get('name') ?? file.name ?? '');
      if (file.size > MAX_JOB_BYTES) throw new G2Fail(10, `${file.size} bytes > ${MAX_JOB_BYTES}`);
      text = await file.text();
    } else {
      const body = await this.body(req);
      if (!isRecord(body) || typeof body.gcode !== 'string')
        throw new G2Fail(101, 'expected {"name":…,"gcode":…}');
      name = typeof body.name === 'string' ? body.name : '';
      text = body.gcode;
      if (text.length > MAX_JOB_BYTES) throw new G2Fail(10, `${text.length} bytes > ${MAX_JOB_BYTES}`);
    }
    const lines = text
      .split(/\r?\n/)
      .map((l) => l.trim())
      .filter((l) => l !== '' && !/^\(.*\)$/.test(l) && !l.startsWith(';'));
    if (lines.length === 0) throw new G2Fail(101, 'the job has no G-code lines');
    return jsonResponse(this.addJob(name, lines).id, 201);
  }

  /** Puts a job at the end of the queue (it waits there for a start). */
  private addJob(name: string, lines: string[]): SimJob {
    const job: SimJob = {
      id: ++this.jobSeq,
      name: name || `job-${this.jobSeq}.nc`,
      lines,
      state: 'queued',
      started: null,
      finished: null,
      operation: null,
    };
    this.jobs.set(job.id, job);
    this.queue.push(job.id);
    // Keep the finished history bounded (the demo loop queues a job every few minutes).
    const done = [...this.jobs.values()].filter((j) => !['queued', 'running', 'paused'].includes(j.state));
    for (const j of done.sort((a, b) => (a.finished ?? 0) - (b.finished ?? 0)).slice(0, -50))
      this.jobs.delete(j.id);
    return job;
  }

  /** Starts a queued job as a `sendfile` operation. */
  private startJob(job: SimJob): void {
    this.queue = this.queue.filter((id) => id !== job.id);
    // State first: addOp runs the first lines at once, and a job may end (in error) right there.
    job.state = 'running';
    job.started = this.now();
    const created = this.addOp('sendfile', String(job.id), job.lines, job.id);
    job.operation = created.id;
  }

  private findJob(id: string): SimJob {
    const job = this.jobs.get(Number(id));
    if (!job) throw new G2Fail(100, `no job ${id}`);
    return job;
  }

  private jobView(job: SimJob): Record<string, unknown> {
    const op = job.operation !== null ? this.ops.get(job.operation) : undefined;
    const pos = this.queue.indexOf(job.id);
    const v: Record<string, unknown> = {
      id: job.id,
      name: job.name,
      state: job.state,
      lines: job.lines.length,
      done: op ? op.done : job.state === 'done' ? job.lines.length : 0,
      started: job.started === null ? null : new Date(job.started).toISOString(),
      finished: job.finished === null ? null : new Date(job.finished).toISOString(),
      operation: job.operation,
      position: pos < 0 ? null : pos,
    };
    if (op?.error) v.error = op.error;
    return v;
  }

  private jobList(): Record<string, unknown>[] {
    const active = [...this.jobs.values()].filter((j) => j.state === 'running' || j.state === 'paused');
    const queued = this.queue.map((id) => this.jobs.get(id)!);
    const finished = [...this.jobs.values()]
      .filter((j) => !active.includes(j) && !queued.includes(j))
      .sort((a, b) => (b.finished ?? 0) - (a.finished ?? 0))
      .slice(0, 20);
    return [...active, ...queued, ...finished].map((j) => this.jobView(j));
  }

  private putJob(job: SimJob, body: unknown): Response {
    if (!isRecord(body)) throw new G2Fail(101, 'expected {"state":…} or {"position":…}');
    if (typeof body.position === 'number') {
      const i = this.queue.indexOf(job.id);
      if (i < 0) throw new G2Fail(106, `job ${job.id} is not queued`);
      const to = Math.max(0, Math.min(this.queue.length - 1, Math.round(body.position)));
      this.queue.splice(i, 1);
      this.queue.splice(to, 0, job.id);
      return jsonResponse(this.jobView(job));
    }
    const op = job.operation !== null ? this.ops.get(job.operation) : undefined;
    switch (body.state) {
      case 'run':
        if (job.state === 'queued') {
          const rejected = this.alarmed();
          if (rejected !== null) throw new G2Fail(rejected, 'clear the alarm first');
          // One job at a time; the next queued job never starts by itself (the operator checks the stock).
          if (this.currentOp()) throw new G2Fail(106, 'the machine is busy with another operation');
          this.startJob(job);
        } else if (op && job.state === 'paused') this.putOperation(op, { opstate: 'run' });
        else throw new G2Fail(106, `job ${job.id} is ${job.state}`);
        break;
      case 'pause':
        if (!op || job.state !== 'running') throw new G2Fail(106, `job ${job.id} is ${job.state}`);
        this.putOperation(op, { opstate: 'pause' });
        break;
      case 'kill':
        if (job.state === 'queued') {
          this.queue = this.queue.filter((id) => id !== job.id);
          job.state = 'killed';
          job.finished = this.now();
        } else if (op && (op.state === 'run' || op.state === 'pend')) this.kill(op);
        else throw new G2Fail(106, `job ${job.id} is ${job.state}`);
        break;
      default:
        throw new G2Fail(101, 'state must be "run", "pause" or "kill"');
    }
    return jsonResponse(this.jobView(job));
  }

  private deleteJob(job: SimJob): Response {
    if (job.state === 'running' || job.state === 'paused')
      throw new G2Fail(106, `job ${job.id} is ${job.state}`);
    this.jobs.delete(job.id);
    this.queue = this.queue.filter((id) => id !== job.id);
    return new Response(null, { status: 204 });
  }

  // ------------------------------------------------------------------------------ controls

  /**
   * The demo loop ("Start a demo job", run automatically for the built-in demo fleet): the
   * simulated operator homes, queues DEMO_JOB_NAME and starts it, and after each successful run
   * waits DEMO_PAUSE_MS (new stock) and runs it again. It works only on the simulator's own state
   * (the same job queue and operations a REST client sees), never through requests, so the
   * console shows it as a job like any other and can hold, resume and kill it. A job that ends
   * killed or in error (an operator's kill, an alarm) ends the loop: a stopped machine stays
   * stopped until someone starts the demo again.
   */
  private demo: { jobId: number | null; restartAt: number | null } | null = null;

  startDemo(): void {
    const id = this.demo?.jobId ?? null;
    const job = id !== null ? this.jobs.get(id) : undefined;
    if (job && ['queued', 'running', 'paused'].includes(job.state)) return;
    this.demo = { jobId: null, restartAt: this.now() };
    this.demoStep();
  }

  /** True while the demo loop is on (a demo job runs or the next one is due). */
  get demoRunning(): boolean {
    return this.demo !== null;
  }

  private demoStep(): void {
    const d = this.demo;
    if (!d) return;
    const job = d.jobId !== null ? this.jobs.get(d.jobId) : undefined;
    if (job && ['queued', 'running', 'paused'].includes(job.state)) return;
    if (job && job.state !== 'done') {
      this.demo = null;
      return;
    }
    if (d.restartAt === null) {
      d.restartAt = this.now() + DEMO_PAUSE_MS;
      return;
    }
    // Wait for a machine that could start: idle, no alarm, nothing else running.
    if (this.now() < d.restartAt || this.currentOp() || ![1, 3, 4].includes(this.stat)) return;
    const next = this.addJob(DEMO_JOB_NAME, demoPocket());
    d.jobId = next.id;
    d.restartAt = null;
    this.startJob(next);
  }

  controls(): SimControl[] {
    return [
      { id: 'demo', label: 'Start a demo job', run: () => this.startDemo() },
      {
        id: 'limit',
        label: 'Trip a limit switch (ALARM)',
        run: () => this.raise(2, 203, 'limit switch hit'),
      },
      { id: 'shutdown', label: 'Shutdown input (SHUTDOWN)', run: () => this.raise(12, 5, 'shutdown input') },
      { id: 'panic', label: 'Panic (PANIC)', run: () => this.raise(13, 6, 'panic') },
      {
        id: 'interlock',
        label: 'Open / close the safety interlock',
        run: () => {
          if (this.stat === 11) {
            // Closed again: a job in progress waits in feedhold for a cycle start.
            const op = this.currentOp();
            this.stat = op && op.state === 'run' ? 6 : 3;
            this.hold = this.stat === 6 ? 4 : 0;
          } else if (this.alarmed() === null) {
            this.stat = 11;
            this.vel = 0;
          }
        },
      },
      {
        id: 'reset',
        label: 'Hard reset / power cycle (^X)',
        run: () => {
          this.raise(1, 6, 'reset');
          this.model = newModel();
          this.drift = {
            x: this.drift.x + this.mpos.x,
            y: this.drift.y + this.mpos.y,
            z: this.drift.z + this.mpos.z,
            a: 0,
            b: 0,
            c: 0,
          };
          this.mpos = zeroVec();
          this.line = 0;
        },
      },
    ];
  }
}

export function createG2coreSimulator(opts: SimOptions): Simulator {
  return new G2coreSimulator(opts);
}
