/**
 * A small G-code interpreter for the simulated g2core: enough of the language for jogs, homing,
 * MDI and jobs (G0/G1 moves at the feed, G2/G3 arcs cut into chords, G4 dwell, G28.2
 * homing, G38.2 probe refusal, units, distance mode, coordinate systems, G92, G10 L2, M codes
 * as no-ops). Errors use the firmware's status codes (status-codes.json). Everything here is
 * simulated.
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

interface Word {
  letter: string;
  value: number;
  text: string;
}

/** Splits a line into words. Comments `( … )` and `; …` are dropped. */
export function tokenize(line: string): Word[] | GError {
  const src = line
    .replace(/\([^)]*\)/g, ' ')
    .replace(/;.*$/, '')
    .toUpperCase();
  const words: Word[] = [];
  let i = 0;
  while (i < src.length) {
    const ch = src[i]!;
    if (ch === ' ' || ch === '\t' || ch === '\r') {
      i++;
      continue;
    }
    if (ch === '%' && words.length === 0) return []; // program delimiter
    if (!/[A-Z]/.test(ch)) return { code: 101, additional: `unexpected "${ch}" in "${line.trim()}"` };
    const m = /^[ \t]*([-+]?(?:\d+\.?\d*|\.\d+))/.exec(src.slice(i + 1));
    if (!m) return { code: 102, additional: `${ch} needs a number in "${line.trim()}"` };
    words.push({ letter: ch, value: Number(m[1]), text: m[1]!.trim() });
    i += 1 + m[0].length;
  }
  return words;
}

const MOTION = new Set(['0', '1', '2', '3', '38.2', '80']);
const SUPPORTED_G = new Set([
  '0',
  '1',
  '2',
  '3',
  '4',
  '10',
  '17',
  '18',
  '19',
  '20',
  '21',
  '28',
  '28.2',
  '28.3',
  '30',
  '38.2',
  '40',
  '49',
  '53',
  '54',
  '55',
  '56',
  '57',
  '58',
  '59',
  '61',
  '61.1',
  '64',
  '80',
  '90',
  '90.1',
  '91',
  '91.1',
  '92',
  '92.1',
  '93',
  '94',
]);
const SUPPORTED_M = new Set([0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 30, 48, 49, 50, 51, 100, 101]);

function gKey(text: string): string {
  const n = Number(text);
  return Number.isInteger(n) ? String(n) : String(n);
}

/**
 * Interprets one line against `m` (mutated on success only when `commit` is called by the
 * caller: the function works on a clone and returns it).
 */
export function interpret(
  model: Model,
  env: InterpEnv,
  rawLine: string,
): { model: Model; actions: Action[] } | { error: GError } {
  const line = rawLine.trim();
  const m = cloneModel(model);
  if (line === '') return { model: m, actions: [] };
  if (line.startsWith('{')) return interpretJson(m, env, line);
  const words = tokenize(line);
  if (!Array.isArray(words)) return { error: words };
  const gs: string[] = [];
  const ms: number[] = [];
  const axes: Partial<Record<Axis, number>> = {};
  const other: Record<string, number> = {};
  for (const w of words) {
    if (w.letter === 'G') {
      const k = gKey(w.text);
      if (!SUPPORTED_G.has(k)) return { error: { code: 131, additional: `G${w.text}` } };
      gs.push(k);
    } else if (w.letter === 'M') {
      if (!SUPPORTED_M.has(w.value)) return { error: { code: 132, additional: `M${w.text}` } };
      ms.push(w.value);
    } else if ('XYZABC'.includes(w.letter)) {
      axes[w.letter.toLowerCase() as Axis] = w.value;
    } else {
      other[w.letter] = w.value;
    }
  }
  const motionGs = gs.filter((g) => MOTION.has(g));
  if (motionGs.length > 1)
    return { error: { code: 133, additional: motionGs.map((g) => `G${g}`).join(' ') } };
  if (other.N !== undefined) m.lineNo = other.N;
  const actions: Action[] = [];
  // Modal settings first (same line wins for the move).
  for (const g of gs) {
    if (g === '17' || g === '18' || g === '19') m.plan = Number(g) - 17;
    else if (g === '20') m.unit = 0;
    else if (g === '21') m.unit = 1;
    else if (['54', '55', '56', '57', '58', '59'].includes(g)) m.coor = Number(g) - 53;
    else if (g === '61') m.path = 0;
    else if (g === '61.1') m.path = 1;
    else if (g === '64') m.path = 2;
    else if (g === '90') m.dist = 0;
    else if (g === '91') m.dist = 1;
    else if (g === '90.1') m.admo = 0;
    else if (g === '91.1') m.admo = 1;
    else if (g === '93') m.frmo = 0;
    else if (g === '94') m.frmo = 1;
  }
  const scale = m.unit === 0 ? 25.4 : 1;
  const linear = (a: Axis) => a === 'x' || a === 'y' || a === 'z';
  if (other.F !== undefined) m.feed = m.frmo === 0 ? other.F : other.F * scale;
  if (other.S !== undefined) m.spindle = other.S;
  for (const a of Object.keys(axes) as Axis[]) {
    if (env.axis(a).am === 0)
      return { error: { code: 137, additional: `${a.toUpperCase()} axis is disabled (am=0)` } };
  }
  const hasAxes = Object.keys(axes).length > 0;

  // Non-modal codes.
  if (gs.includes('4')) {
    const p = other.P;
    if (p === undefined) return { error: { code: 160, additional: 'G4 needs P (seconds)' } };
    if (p < 0) return { error: { code: 163, additional: `P${p}` } };
    actions.push({ t: 'dwell', ms: p * 1000 });
  }
  if (gs.includes('10')) {
    const l = other.L;
    const p = other.P;
    if (l !== 2) return { error: { code: 173, additional: 'only G10 L2 is supported' } };
    if (p === undefined || p < 1 || p > 6 || !Number.isInteger(p))
      return { error: { code: 161, additional: `P${p}` } };
    const v: Partial<AxisVec> = {};
    for (const [a, val] of Object.entries(axes) as [Axis, number][]) v[a] = linear(a) ? val * scale : val;
    env.setOffset(`g${53 + p}`, v);
    return { model: m, actions };
  }
  if (gs.includes('92')) {
    const off = env.offset('g92');
    const co = env.offset(`g${53 + m.coor}`);
    const v: Partial<AxisVec> = {};
    for (const [a, val] of Object.entries(axes) as [Axis, number][]) {
      v[a] = m.pos[a] - co[a] - (linear(a) ? val * scale : val);
    }
    env.setOffset('g92', { ...off, ...v });
    return { model: m, actions };
  }
  if (gs.includes('92.1')) {
    env.setOffset('g92', zeroVec());
    return { model: m, actions };
  }
  if (gs.includes('28.2')) {
    if (!hasAxes) return { error: { code: 241, additional: 'G28.2 needs axis words (G28.2 X0 Y0 Z0)' } };
    // Firmware order: Z first, then X, Y, A, B, C.
    const order: Axis[] = ['z', 'x', 'y', 'a', 'b', 'c'];
    const list = order.filter((a) => a in axes);
    for (const a of list) {
      const ax = env.axis(a);
      if (ax.hi === 0)
        return { error: { code: 246, additional: `${a.toUpperCase()} has no homing input (hi=0)` } };
      if (ax.sv === 0) return { error: { code: 242, additional: a.toUpperCase() } };
      if (ax.lv === 0) return { error: { code: 243, additional: a.toUpperCase() } };
      if (ax.tn === ax.tm) return { error: { code: 244, additional: a.toUpperCase() } };
    }
    for (const a of list) {
      const ax = env.axis(a);
      m.homed[a] = true;
      m.pos[a] = ax.hd === 1 ? ax.tm : ax.tn;
    }
    actions.push({ t: 'home', axes: list });
    return { model: m, actions };
  }
  if (gs.includes('28.3')) {
    for (const [a, val] of Object.entries(axes) as [Axis, number][]) {
      m.pos[a] = linear(a) ? val * scale : val;
      m.homed[a] = true;
    }
    return { model: m, actions };
  }
  if (gs.includes('38.2')) {
    if (!env.probeConfigured)
      return { error: { code: 252, additional: 'no digital input has the probe function' } };
  }
  if (gs.includes('28') || gs.includes('30')) {
    const target = env.offset(gs.includes('28') ? 'g28' : 'g30');
    return move(m, env, { ...m.pos, ...target }, true, actions);
  }

  const motion = motionGs[0];
  if (motion !== undefined) m.momo = motion === '80' ? 4 : motion === '38.2' ? 5 : Number(motion);
  const arcWords = ['I', 'J', 'K', 'R'].some((w) => other[w] !== undefined);
  if ((m.momo === 2 || m.momo === 3) && (hasAxes || arcWords)) {
    const g53 = gs.includes('53');
    const co = env.offset(`g${53 + m.coor}`);
    const g92 = env.offset('g92');
    const to: AxisVec = { ...m.pos };
    for (const [a, raw] of Object.entries(axes) as [Axis, number][]) {
      const v = linear(a) ? raw * scale : raw;
      if (m.dist === 1 && !g53) to[a] = m.pos[a] + v;
      else to[a] = g53 ? v : v + co[a] + g92[a];
    }
    const rotary = (Object.keys(axes) as Axis[]).filter((a) => !linear(a));
    if (rotary.length > 0)
      return { error: { code: 155, additional: rotary.map((a) => a.toUpperCase()).join(' ') } };
    return arc(m, env, to, { co, g92, scale, other, cw: m.momo === 2 }, actions);
  }
  if (hasAxes && m.momo <= 3) {
    const g53 = gs.includes('53');
    const co = env.offset(`g${53 + m.coor}`);
    const g92 = env.offset('g92');
    const to: AxisVec = { ...m.pos };
    for (const [a, raw] of Object.entries(axes) as [Axis, number][]) {
      const v = linear(a) ? raw * scale : raw;
      if (m.dist === 1 && !g53) to[a] = m.pos[a] + v;
      else to[a] = g53 ? v : v + co[a] + g92[a];
    }
    return move(m, env, to, m.momo === 0, actions);
  }
  if (ms.includes(2) || ms.includes(30)) {
    m.dist = 0;
    m.frmo = 1;
    m.momo = 1;
    m.spindle = 0;
    actions.push({ t: 'end' });
  }
  return { model: m, actions };
}

/**
 * G2/G3 in the selected plane (G17 XY, G18 XZ, G19 YZ, the firmware's axis order) with the
 * third linear axis moving along (helix): centre from I/J/K (incremental with G91.1, absolute
 * with G90.1) or from R, then cut into chords of about 2 mm, each a move at the feed. Errors
 * are the firmware's arc codes (153-159); a chord past a soft limit is 233 (soft limit during arc).
 */
function arc(
  m: Model,
  env: InterpEnv,
  to: AxisVec,
  o: { co: AxisVec; g92: AxisVec; scale: number; other: Record<string, number>; cw: boolean },
  actions: Action[],
): { model: Model; actions: Action[] } | { error: GError } {
  const planes: [Axis, Axis, Axis, string, string][] = [
    ['x', 'y', 'z', 'I', 'J'],
    ['x', 'z', 'y', 'I', 'K'],
    ['y', 'z', 'x', 'J', 'K'],
  ];
  const [p, q, lin, wp, wq] = planes[m.plan] ?? planes[0]!;
  const start = { ...m.pos };
  const dp = to[p] - start[p];
  const dq = to[q] - start[q];
  const closed = Math.abs(dp) < 1e-9 && Math.abs(dq) < 1e-9;
  let cp: number;
  let cq: number;
  const r = o.other.R;
  if (r !== undefined) {
    if (closed) return { error: { code: 159, additional: 'an R arc needs an end point' } };
    const radius = r * o.scale;
    const disc = 4 * radius * radius - dp * dp - dq * dq;
    if (disc < -1e-6) return { error: { code: 154, additional: `R${r} is shorter than half the chord` } };
    let h = -Math.sqrt(Math.max(0, disc)) / Math.hypot(dp, dq);
    if (!o.cw) h = -h;
    if (radius < 0) h = -h;
    cp = start[p] + 0.5 * (dp - dq * h);
    cq = start[q] + 0.5 * (dq + dp * h);
  } else {
    const ip = o.other[wp];
    const iq = o.other[wq];
    if (ip === undefined && iq === undefined)
      return { error: { code: 157, additional: `${wp}/${wq} for the selected plane` } };
    if (m.admo === 0) {
      cp = (ip ?? 0) * o.scale + o.co[p] + o.g92[p];
      cq = (iq ?? 0) * o.scale + o.co[q] + o.g92[q];
    } else {
      cp = start[p] + (ip ?? 0) * o.scale;
      cq = start[q] + (iq ?? 0) * o.scale;
    }
  }
  const r0 = Math.hypot(start[p] - cp, start[q] - cq);
  const r1 = Math.hypot(to[p] - cp, to[q] - cq);
  if (r0 < 1e-6) return { error: { code: 154, additional: 'the centre is the start point' } };
  if (Math.abs(r0 - r1) > Math.max(0.05, 0.001 * r0))
    return { error: { code: 158, additional: `start radius ${round(r0)} ≠ end radius ${round(r1)}` } };
  const a0 = Math.atan2(start[q] - cq, start[p] - cp);
  const a1 = Math.atan2(to[q] - cq, to[p] - cp);
  let sweep = a1 - a0;
  if (closed) sweep = o.cw ? -2 * Math.PI : 2 * Math.PI;
  else if (o.cw && sweep >= 0) sweep -= 2 * Math.PI;
  else if (!o.cw && sweep <= 0) sweep += 2 * Math.PI;
  const n = Math.min(360, Math.max(4, Math.ceil((Math.abs(sweep) * r0) / 2)));
  let cur: Model = m;
  for (let k = 1; k <= n; k++) {
    const f = k / n;
    const point: AxisVec =
      k === n
        ? { ...to }
        : {
            ...to,
            [p]: cp + r0 * Math.cos(a0 + sweep * f),
            [q]: cq + r0 * Math.sin(a0 + sweep * f),
            [lin]: start[lin] + (to[lin] - start[lin]) * f,
          };
    const r2 = move(cur, env, point, false, actions);
    if ('error' in r2) {
      const soft = r2.error.code >= 221 && r2.error.code <= 232;
      return soft ? { error: { code: 233, additional: r2.error.additional } } : r2;
    }
    cur = r2.model;
  }
  return { model: cur, actions };
}

function move(
  m: Model,
  env: InterpEnv,
  to: AxisVec,
  rapid: boolean,
  actions: Action[],
): { model: Model; actions: Action[] } | { error: GError } {
  // Soft limits (sl=1) apply to homed axes with distinct travel min and max, as in the firmware.
  if (env.softLimits) {
    for (const [i, a] of AXES.entries()) {
      const ax = env.axis(a);
      if (!m.homed[a] || ax.tn === ax.tm || to[a] === m.pos[a]) continue;
      if (to[a] < ax.tn)
        return { error: { code: 221 + i * 2, additional: `${a.toUpperCase()} ${round(to[a])} < ${ax.tn}` } };
      if (to[a] > ax.tm)
        return { error: { code: 222 + i * 2, additional: `${a.toUpperCase()} ${round(to[a])} > ${ax.tm}` } };
    }
  }
  let dist2 = 0;
  let minMs = 0;
  for (const a of AXES) {
    const d = Math.abs(to[a] - m.pos[a]);
    if (d === 0) continue;
    dist2 += d * d;
    const ax = env.axis(a);
    const limit = rapid ? ax.vm : ax.fr;
    if (limit > 0) minMs = Math.max(minMs, (d / limit) * 60_000);
  }
  const dist = Math.sqrt(dist2);
  let ms = minMs;
  let rate = 0;
  if (!rapid) {
    if (m.feed <= 0) return { error: { code: 142, additional: 'G1/G2/G3 need an F word' } };
    const feedMs = m.frmo === 0 ? 60_000 / m.feed : (dist / (m.feed * env.feedOverride)) * 60_000;
    ms = Math.max(ms, feedMs);
  }
  rate = ms > 0 ? (dist / ms) * 60_000 : 0;
  if (dist > 0) actions.push({ t: 'move', to, ms, rate });
  m.pos = to;
  return { model: m, actions };
}

function interpretJson(m: Model, env: InterpEnv, line: string) {
  let parsed: unknown;
  try {
    // Relaxed JSON ({xvm:n}) is accepted by the firmware: quote bare keys, n/t/f literals.
    const strict = line
      .replace(/([{,]\s*)([A-Za-z0-9_.]+)\s*:/g, '$1"$2":')
      .replace(/:\s*n\b/g, ':null')
      .replace(/:\s*t\b/g, ':true')
      .replace(/:\s*f\b/g, ':false');
    parsed = JSON.parse(strict);
  } catch {
    return { error: { code: 111, additional: line } };
  }
  if (typeof parsed !== 'object' || parsed === null || Array.isArray(parsed)) {
    return { error: { code: 101, additional: line } };
  }
  const values = parsed as Record<string, unknown>;
  for (const [k, v] of Object.entries(values)) {
    const e = env.checkJson(k, v);
    if (e) return { error: e };
  }
  return { model: m, actions: [{ t: 'json', values } as Action] };
}

export function round(v: number, digits = 3): number {
  const f = 10 ** digits;
  return Math.round(v * f) / f;
}
