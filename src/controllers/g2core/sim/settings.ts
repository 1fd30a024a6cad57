import { G2Fail, isRecord } from './fail';
import { AXES, round, type AxisVec, type InterpEnv } from './model';
import { G2coreState, type Scalar } from './state';

/**
 * The settings tree of the simulated g2core (the 100.12 dump in `cfg`): keys in all their
 * spellings, reads, filters, validated sets with the firmware's status codes, and the view of the
 * settings the G-code interpreter works with. The second layer of the simulator.
 */

const READ_ONLY_SYS = new Set(['fb', 'fbs', 'fbc', 'fv', 'hp', 'hv', 'id']);
const READ_ONLY_HEATER = new Set(['t', 'op', 'tr', 'at', 'an']);
/** Whole groups the firmware refuses to set over JSON: G92 offsets and the G28/G30 positions are set by G-code. */
const READ_ONLY_GROUPS = new Set(['g92', 'g28', 'g30']);
const OVERRIDES = new Set(['mfo', 'mto', 'sso']);
export const COMMAND_KEYS = new Set(['clear', 'clr', 'alarm', 'shutd', 'panic']);

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

export abstract class G2coreSettings extends G2coreState {
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

  protected readValue(rawKey: string): unknown {
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
  protected validateSet(rawKey: string, value: unknown, dryRun: boolean): void {
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

  protected applySet(rawKey: string, value: unknown): void {
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
  protected select(spec: Record<string, unknown>, source: 'machine' | 'status'): Record<string, unknown> {
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

  /**
   * The settings as the G-code interpreter sees them. With `dry`, offsets set by the lines
   * (G10 L2, G92) stay in this environment and the tree does not change.
   */
  protected env(dry: boolean): InterpEnv {
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
}
