/**
 * A synthetic Prunt config N times the size of a real one (for prunt-page.bench.ts): every
 * top-level section keeps its place, and its children (steppers, heaters, kinematics settings…)
 * are repeated N times, copies renamed "<key> (2)" … "<key> (N)". Schema, values and the values'
 * errors are scaled alike, so the console builds, fills and validates N times the settings. Both
 * API generations (wire.ts): module (`{"Prunt config version","Config":{module:{Version,Config}}}`)
 * and flat (`{section: node}`, values keyed by `$`-joined names).
 */
import type { WireNode } from '../../src/controllers/prunt/wire';

type Obj = Record<string, unknown>;

const isObj = (v: unknown): v is Obj => typeof v === 'object' && v !== null && !Array.isArray(v);

export interface ScaledConfig {
  /** `GET /config/schema`'s answer. */
  schemaText: string;
  /** `GET /config/values`'s answer (`{"Values","Errors"}`). */
  valuesText: string;
  /** Leaf values in the answer (a ratio counts twice, as the flat API's keys do). */
  settings: number;
}

const copyKey = (key: string, copy: number): string => (copy === 1 ? key : `${key} (${copy})`);

/** Children repeated `factor` times: originals first, then every copy in the same order. */
function repeatChildren<T>(children: Record<string, T>, factor: number): Record<string, T> {
  const out: Record<string, T> = {};
  for (let c = 1; c <= factor; c++) for (const [k, v] of Object.entries(children)) out[copyKey(k, c)] = v;
  return out;
}

function scaleSection(n: WireNode, factor: number): WireNode {
  return n.Children ? { ...n, Children: repeatChildren(n.Children, factor) } : n;
}

/** Primitive leaves under `v`. */
function countLeaves(v: unknown): number {
  if (Array.isArray(v)) return v.reduce((a: number, x) => a + countLeaves(x), 0);
  if (isObj(v)) return Object.values(v).reduce((a: number, x) => a + countLeaves(x), 0);
  return 1;
}

/** Scales a config schema and its values (as the controller answered them) by `factor`. */
export function scaleConfig(schemaText: string, valuesText: string, factor: number): ScaledConfig {
  if (!Number.isInteger(factor) || factor < 1)
    throw new Error(`factor must be a whole number ≥ 1, not ${factor}`);
  const schema = JSON.parse(schemaText) as unknown;
  const values = JSON.parse(valuesText) as unknown;
  if (!isObj(schema) || !isObj(values) || !isObj(values['Values']))
    throw new Error('not a Prunt config schema and values answer');
  const errors = Array.isArray(values['Errors']) ? (values['Errors'] as unknown[]) : [];
  return 'Prunt config version' in schema
    ? scaleModule(schema, values['Values'], errors, factor)
    : scaleFlat(schema as Record<string, WireNode>, values['Values'], errors, factor);
}

// --------------------------------------------------------------------------- module API

interface Module<T> {
  Version: number;
  Config: Record<string, T>;
}

function scaleModule(schema: Obj, values: Obj, errors: unknown[], factor: number): ScaledConfig {
  const config = schema['Config'] as Record<string, Module<WireNode>>;
  const outSchema: Record<string, Module<WireNode>> = {};
  for (const [m, mod] of Object.entries(config)) {
    const props: Record<string, WireNode> = {};
    for (const [k, n] of Object.entries(mod.Config)) props[k] = scaleSection(n, factor);
    outSchema[m] = { ...mod, Config: props };
  }
  const vconfig = isObj(values['Config']) ? (values['Config'] as Record<string, Module<unknown>>) : {};
  const outValues: Record<string, Module<unknown>> = {};
  let settings = 0;
  for (const [m, mod] of Object.entries(vconfig)) {
    const props: Obj = {};
    for (const [k, v] of Object.entries(mod.Config)) props[k] = isObj(v) ? repeatChildren(v, factor) : v;
    outValues[m] = { ...mod, Config: props };
    settings += countLeaves(props);
  }
  // Errors: ["Config", module, "Config", section, child, …]: one per copy of the child.
  const outErrors: unknown[] = [];
  for (const e of errors) {
    const path = isObj(e) && Array.isArray(e['Path']) ? (e['Path'] as unknown[]) : null;
    if (!path || path.length < 5 || typeof path[4] !== 'string') {
      outErrors.push(e);
      continue;
    }
    for (let c = 1; c <= factor; c++)
      outErrors.push({ ...(e as Obj), Path: [...path.slice(0, 4), copyKey(path[4], c), ...path.slice(5)] });
  }
  return {
    schemaText: JSON.stringify({ ...schema, Config: outSchema }),
    valuesText: JSON.stringify({ Values: { ...values, Config: outValues }, Errors: outErrors }),
    settings,
  };
}

// --------------------------------------------------------------------------- flat API

/** "Section$child$rest" → the copy's key; keys without a child (no second segment) stay. */
function flatCopy(key: string, copy: number): string {
  const parts = key.split('$');
  if (parts.length < 2 || copy === 1) return key;
  return [parts[0], copyKey(parts[1] as string, copy), ...parts.slice(2)].join('$');
}

function scaleFlat(
  schema: Record<string, WireNode>,
  values: Obj,
  errors: unknown[],
  factor: number,
): ScaledConfig {
  const outSchema: Record<string, WireNode> = {};
  for (const [k, n] of Object.entries(schema)) outSchema[k] = scaleSection(n, factor);
  const outValues: Obj = {};
  for (let c = 1; c <= factor; c++)
    for (const [k, v] of Object.entries(values)) outValues[flatCopy(k, c)] = v;
  const outErrors: unknown[] = [];
  for (const e of errors) {
    const key = isObj(e) && typeof e['Key'] === 'string' ? e['Key'] : null;
    if (key === null) outErrors.push(e);
    else for (let c = 1; c <= factor; c++) outErrors.push({ ...(e as Obj), Key: flatCopy(key, c) });
  }
  return {
    schemaText: JSON.stringify(outSchema),
    valuesText: JSON.stringify({ Values: outValues, Errors: outErrors }),
    settings: Object.keys(outValues).length,
  };
}

/** Leaf values in a `GET /config/values` answer (module or flat), as `ScaledConfig.settings` counts them. */
export function countSettings(valuesText: string): number {
  const v = (JSON.parse(valuesText) as { Values?: unknown }).Values;
  if (!isObj(v)) return 0;
  if (!isObj(v['Config'])) return Object.keys(v).length;
  let n = 0;
  for (const mod of Object.values(v['Config'])) if (isObj(mod)) n += countLeaves(mod['Config']);
  return n;
}
