/**
 * The planner model of the simulated g2core and what the interpreter (gcode.ts) and the moves it
 * plans (moves.ts) share: axes, modal state, actions, errors and the view of the settings.
 * Everything here is simulated.
 */

export const AXES = ['x', 'y', 'z', 'a', 'b', 'c'] as const;
export type Axis = (typeof AXES)[number];
export type AxisVec = Record<Axis, number>;

export const zeroVec = (): AxisVec => ({ x: 0, y: 0, z: 0, a: 0, b: 0, c: 0 });

export interface Model {
  /** Planned machine position (mm / degrees) after the lines interpreted so far. */
  pos: AxisVec;
  unit: number; // 0 G20, 1 G21
  coor: number; // 1..6 = G54..G59
  dist: number; // 0 G90, 1 G91
  admo: number;
  frmo: number; // 0 G93, 1 G94
  momo: number;
  plan: number;
  path: number;
  /** Programmed feed in mm/min (0 = none yet). Under G93 the inverse-time value. */
  feed: number;
  homed: Record<Axis, boolean>;
  /** N word of the last line, or null. */
  lineNo: number | null;
  spindle: number;
}

export type Action =
  | { t: 'move'; to: AxisVec; ms: number; rate: number }
  | { t: 'dwell'; ms: number }
  | { t: 'home'; axes: Axis[] }
  | { t: 'end' }
  | { t: 'json'; values: Record<string, unknown> };

export interface GError {
  code: number;
  additional: string;
}

/** What the interpreter needs from the machine's settings. */
export interface InterpEnv {
  axis(a: Axis): {
    am: number;
    vm: number;
    fr: number;
    tn: number;
    tm: number;
    hi: number;
    hd: number;
    sv: number;
    lv: number;
  };
  softLimits: boolean;
  feedOverride: number;
  offset(group: string): AxisVec;
  setOffset(group: string, v: Partial<AxisVec>): void;
  probeConfigured: boolean;
  /** Validates a JSON line's key/value; returns an error or null. */
  checkJson(key: string, value: unknown): GError | null;
}

export function newModel(): Model {
  return {
    pos: zeroVec(),
    unit: 1,
    coor: 1,
    dist: 0,
    admo: 1,
    frmo: 1,
    momo: 0,
    plan: 0,
    path: 2,
    feed: 0,
    homed: { x: false, y: false, z: false, a: false, b: false, c: false },
    lineNo: null,
    spindle: 0,
  };
}

export function cloneModel(m: Model): Model {
  return { ...m, pos: { ...m.pos }, homed: { ...m.homed } };
}

export function round(v: number, digits = 3): number {
  const f = 10 ** digits;
  return Math.round(v * f) / f;
}
