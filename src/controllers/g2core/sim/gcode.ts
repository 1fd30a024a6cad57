import { arc, move } from './moves';
import {
  cloneModel,
  zeroVec,
  type Action,
  type Axis,
  type AxisVec,
  type GError,
  type InterpEnv,
  type Model,
} from './model';

/**
 * A small G-code interpreter for the simulated g2core: enough of the language for jogs, homing,
 * MDI and jobs (G0/G1 moves at the feed, G2/G3 arcs cut into chords, G4 dwell, G28.2
 * homing, G38.2 probe refusal, units, distance mode, coordinate systems, G92, G10 L2, M codes
 * as no-ops). Errors use the firmware's status codes (status-codes.json). Everything here is
 * simulated.
 */

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
