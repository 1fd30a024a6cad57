import type { SimOptions } from '../../../fleet/sim';
import configGroups from './data/config-groups-100.12.json' with { type: 'json' };
import { AXES, newModel, round, zeroVec, type Action, type Axis, type AxisVec, type Model } from './model';

/**
 * The simulated g2core's state, and the status report built from it: the first layer of the
 * simulator (see simulator.ts for the layers). Every field of the simulated controller is
 * declared here, once, so that the layers above only add behaviour.
 */

export type Group = Record<string, string | number | boolean | null>;
export type Scalar = string | number | boolean | null;

export interface Op {
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

export interface SimJob {
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
export interface HomeLeg {
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

export type SimAction = Action | HomeLeg;

export interface Running {
  action: SimAction;
  elapsed: number;
  from: AxisVec;
  /** Homing: the planned end position. */
  to: AxisVec;
  ms: number;
  rate: number;
}

/** The demo loop's progress (jobs.ts). */
export interface DemoLoop {
  jobId: number | null;
  restartAt: number | null;
}

export abstract class G2coreState {
  readonly cfg: Record<string, Group>;
  protected readonly now: () => number;
  private readonly timer: ReturnType<typeof setInterval>;
  protected last: number;
  /** Planner model: position and modal state after everything executed so far. */
  model: Model = newModel();
  /** Machine position as the controller believes it (mm). */
  mpos: AxisVec = zeroVec();
  /** Physical position minus believed position: unknown until homed. */
  protected drift: AxisVec = { x: 150, y: 100, z: -30, a: 0, b: 0, c: 0 };
  stat = 1;
  hold = 0;
  vel = 0;
  line = 0;
  protected ended = false;
  protected ops = new Map<number, Op>();
  protected opSeq = 41;
  protected jobs = new Map<number, SimJob>();
  protected queue: number[] = [];
  protected jobSeq = 0;
  protected running: Running | null = null;
  protected pending: SimAction[] = [];
  protected ticking = false;
  /**
   * The demo loop ("Start a demo job", run automatically for the built-in demo fleet): the
   * simulated operator homes, queues DEMO_JOB_NAME and starts it, and after each successful run
   * waits DEMO_PAUSE_MS (new stock) and runs it again. It works only on the simulator's own state
   * (the same job queue and operations a REST client sees), never through requests, so the
   * console shows it as a job like any other and can hold, resume and kill it. A job that ends
   * killed or in error (an operator's kill, an alarm) ends the loop: a stopped machine stays
   * stopped until someone starts the demo again.
   */
  protected demo: DemoLoop | null = null;

  constructor(protected readonly opts: SimOptions) {
    this.now = opts.now ?? Date.now;
    this.cfg = structuredClone(configGroups) as Record<string, Group>;
    this.cfg.sys!.sl = 1;
    this.last = this.now();
    this.timer = setInterval(() => this.tick(), opts.tickMs ?? 50);
  }

  dispose(): void {
    clearInterval(this.timer);
  }

  /** Lets time pass: runs the demo loop and the motion in progress (motion.ts). */
  abstract tick(): void;

  /** One step of the demo loop (jobs.ts). */
  protected abstract demoStep(): void;

  // ------------------------------------------------------------------------------ world

  protected num(group: string, key: string): number {
    const v = this.cfg[group]?.[key];
    return typeof v === 'number' ? v : typeof v === 'boolean' ? (v ? 1 : 0) : Number(v ?? 0) || 0;
  }

  protected offsetOf(group: string): AxisVec {
    const g = this.cfg[group] ?? {};
    const v = zeroVec();
    for (const a of AXES) v[a] = typeof g[a] === 'number' ? (g[a] as number) : 0;
    return v;
  }

  protected busy(): boolean {
    return [5, 6, 7, 9, 10].includes(this.stat);
  }

  protected alarmed(): number | null {
    if (this.stat === 2) return 204;
    if (this.stat === 12) return 205;
    if (this.stat === 13) return 206;
    return null;
  }

  protected currentOp(): Op | null {
    for (const op of this.ops.values()) if (op.state === 'run' || op.state === 'pend') return op;
    return null;
  }

  protected unitScale(): number {
    return this.model.unit === 0 ? 25.4 : 1;
  }

  // ------------------------------------------------------------------------------ status

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
}
