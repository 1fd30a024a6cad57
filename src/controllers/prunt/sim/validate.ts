import type { WireNode } from '../wire';
import type { FlatSchema, FlatValues } from './board';

/**
 * Server-side validation as Prunt does it (prunt-config.adb at f929604, per SOURCES.md):
 * 1. `Validate_Config_To_Schema`: every posted key against the schema. Any failure and nothing is
 *    saved; each message starts with "Data does not match schema, no values will be saved: ".
 *    Texts verbatim from the fixture where it has them (less than, denominator, integer, unknown
 *    key); the others follow the same style (marked "sim:").
 * 2. `Validate_Config`: semantic checks over the whole saved config; the values ARE saved.
 */

export const SCHEMA_PREFIX = 'Data does not match schema, no values will be saved: ';

export interface KeyError {
  Key: string;
  Message: string;
}

/** Ada `Long_Float'Image` without the leading space: 1.00000000000000E-06. */
export function adaImage(n: number): string {
  const [mant, exp] = n.toExponential(14).split('e');
  const e = Number(exp);
  const sign = e < 0 ? '-' : '+';
  return `${mant}E${sign}${String(Math.abs(e)).padStart(2, '0')}`;
}

interface LeafInfo {
  node: WireNode;
  /** For ratio parts: which part. */
  part?: 'Numerator' | 'Denominator';
  ratioKey?: string;
}

const indexCache = new WeakMap<FlatSchema, Map<string, LeafInfo>>();

export function leafIndex(schema: FlatSchema): Map<string, LeafInfo> {
  const hit = indexCache.get(schema);
  if (hit) return hit;
  const idx = new Map<string, LeafInfo>();
  const walk = (n: WireNode, key: string) => {
    switch (n.Kind) {
      case 'Sequence':
      case 'Tabbed_Sequence':
        for (const [k, c] of Object.entries(n.Children ?? {})) walk(c, `${key}$${k}`);
        return;
      case 'Variant':
        idx.set(key, { node: n });
        for (const [k, c] of Object.entries(n.Children ?? {})) walk(c, `${key}$${k}`);
        return;
      case 'Float_Ratio':
        idx.set(`${key}$Numerator`, { node: n, part: 'Numerator', ratioKey: key });
        idx.set(`${key}$Denominator`, { node: n, part: 'Denominator', ratioKey: key });
        return;
      default:
        idx.set(key, { node: n });
    }
  };
  for (const [k, n] of Object.entries(schema)) walk(n, k);
  indexCache.set(schema, idx);
  return idx;
}

export function validateToSchema(
  schema: FlatSchema,
  patch: Record<string, unknown>,
  current: FlatValues,
): KeyError[] {
  const idx = leafIndex(schema);
  const errors: KeyError[] = [];
  const err = (Key: string, m: string) => errors.push({ Key, Message: SCHEMA_PREFIX + m });
  for (const [key, v] of Object.entries(patch)) {
    const info = idx.get(key);
    if (!info) {
      err(key, 'Key is not a recognised parameter name.');
      continue;
    }
    const n = info.node;
    switch (n.Kind) {
      case 'Boolean':
        if (typeof v !== 'boolean') err(key, 'Element must be a boolean.'); // sim:
        break;
      case 'Discrete':
        if (typeof v !== 'string' || !(n.Options ?? []).includes(v))
          err(key, 'Element must be one of the allowed options.'); // sim:
        break;
      case 'Variant':
        if (typeof v !== 'string' || !Object.keys(n.Children ?? {}).includes(v))
          err(key, 'Element must be one of the allowed options.'); // sim:
        break;
      case 'String':
        if (typeof v !== 'string') err(key, 'Element must be a string.'); // sim:
        break;
      case 'Integer':
      case 'Float': {
        if (typeof v !== 'number') {
          err(key, 'Element must be a number.'); // sim:
          break;
        }
        if (n.Kind === 'Integer' && !Number.isInteger(v)) {
          err(key, 'Element must be integer, floats are not allowed even if they are whole numbers.');
          break;
        }
        if (n.Min !== undefined && v < n.Min) err(key, `Element must not be less than ${adaImage(n.Min)}`);
        else if (n.Max !== undefined && v > n.Max)
          err(key, `Element must not be greater than ${adaImage(n.Max)}`); // sim: mirrors "less than"
        break;
      }
      case 'Float_Ratio': {
        if (typeof v !== 'number') {
          err(key, 'Element must be a number.'); // sim:
          break;
        }
        if (info.part === 'Denominator' && v === 0) {
          err(key, 'Denominator must not be zero.');
          break;
        }
        const rk = info.ratioKey as string;
        const num = Number(patch[`${rk}$Numerator`] ?? current[`${rk}$Numerator`]);
        const den = Number(patch[`${rk}$Denominator`] ?? current[`${rk}$Denominator`]);
        if (info.part === 'Numerator' && den !== 0 && Number.isFinite(num / den)) {
          const r = num / den;
          if (n.Min !== undefined && r < n.Min)
            err(key, `Ratio must not be less than ${adaImage(n.Min)}`); // sim:
          else if (n.Max !== undefined && r > n.Max)
            err(key, `Ratio must not be greater than ${adaImage(n.Max)}`); // sim:
        }
        break;
      }
    }
  }
  return errors;
}

/** Semantic checks over the whole config (`Validate_Config`); the values are saved anyway. */
export function validateConfig(values: FlatValues): KeyError[] {
  const errors: KeyError[] = [];
  if (values['Prunt$Enabled'] === false) {
    errors.push({ Key: 'Prunt$Enabled', Message: 'Prunt is disabled. Enable after setting other options.' });
  }
  for (let i = 1; i <= 4; i++) {
    const f = `Fans$FAN_${i}`;
    const freq = values[`${f}$PWM frequency`];
    const high = values[`${f}$Use high-side switching`];
    if (typeof freq !== 'number' || typeof high !== 'boolean') continue;
    if (high && freq > 100) {
      errors.push({
        Key: `${f}$PWM frequency`,
        Message: `Fan frequency must be less than or equal to ${adaImage(100)} Hz when in high-side switching mode, which is currently selected (the limit is ${adaImage(25000)} in low-side mode).`,
      });
    } else if (!high && freq > 25000) {
      // sim: the low-side counterpart of the verbatim high-side message.
      errors.push({
        Key: `${f}$PWM frequency`,
        Message: `Fan frequency must be less than or equal to ${adaImage(25000)} Hz when in low-side switching mode, which is currently selected (the limit is ${adaImage(100)} in high-side mode).`,
      });
    }
  }
  // sim: stand-in for the derived SpreadCycle heating checks (the sources give no verbatim text):
  // an enabled driver in derived SpreadCycle mode may not dissipate more than 10 W in the coils.
  for (let i = 1; i <= 6; i++) {
    const s = `Steppers$STEPPER_${i}`;
    if (values[`${s}$Enabled`] !== true) continue;
    if (values[`${s}$CHM`] !== 'SpreadCycle' || values[`${s}$CHM$SpreadCycle`] !== 'Derived') continue;
    const cur = Number(values[`${s}$Run current`]);
    const r = Number(values[`${s}$CHM$SpreadCycle$Derived$Phase resistance`]);
    const watts = cur * cur * r;
    if (Number.isFinite(watts) && watts > 10) {
      errors.push({
        Key: `${s}$Run current`,
        Message: `Derived SpreadCycle settings would overheat the motor: run current squared times phase resistance is ${adaImage(watts)} W, more than ${adaImage(10)} W.`,
      });
    }
  }
  return errors;
}
