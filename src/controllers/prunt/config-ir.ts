import type { FormNode, FormSchema, FormValue, PresentWhen } from '../../forms/ir';
import { toNumber } from '../../forms/ir';
import type { Change } from '../../forms/model';
import type {
  ConfigErrorWire,
  ConfigSchemaWire,
  FlatConfigSchema,
  ModuleConfigSchema,
  WireNode,
} from './wire';

/**
 * Prunt config schema (both API generations) → the form engine's IR, Prunt values → form values,
 * form changes → the patch `POST /config/values` wants, and server error Key/Path → form node.
 *
 * Node ids are `$`-joined names. On the flat API they are exactly the wire keys
 * ("Steppers$STEPPER_1$Run current"); on the module API they start with the module name and skip
 * the wire's "Config"/"Children" segments ("Fans$Fans$FAN_1$Control_Method$Kind").
 */

export type PruntApi = 'module' | 'flat';

export interface PruntForm {
  api: PruntApi;
  form: FormSchema;
  /** Module API: the value path of each node ["Config", module, "Config", …]. */
  wirePath: Map<string, string[]>;
  /** Module API: module versions, required in every patch. */
  moduleVersions: Record<string, number>;
  configVersion: number;
}

const SEP = '$';

export function htmlToText(html: string): string {
  return html
    .replace(/<[^>]*>/g, ' ')
    .replace(/&nbsp;/g, ' ')
    .replace(/&lt;/g, '<')
    .replace(/&gt;/g, '>')
    .replace(/&amp;/g, '&')
    .replace(/\s+/g, ' ')
    .trim();
}

/** A small, stable hash (FNV-1a) of the schema text: the flat API sends no version. */
export function hashText(s: string): string {
  let h = 0x811c9dc5;
  for (let i = 0; i < s.length; i++) {
    h ^= s.charCodeAt(i);
    h = Math.imul(h, 0x01000193);
  }
  return (h >>> 0).toString(16).padStart(8, '0');
}

export function buildForm(wire: ConfigSchemaWire, rawText?: string): PruntForm {
  return wire.api === 'flat' ? buildFlat(wire.schema, rawText) : buildModule(wire.schema);
}

function mapNode(
  nodes: Map<string, FormNode>,
  id: string,
  key: string,
  parent: string | null,
  w: WireNode,
  inModule: string | null,
  wirePath: Map<string, string[]> | null,
  path: string[],
  pending: Array<{ id: string; owner: string; path: string[]; values: unknown[] }>,
): void {
  const base = {
    id,
    key,
    label: key,
    description: w.Description ?? '',
    searchText: htmlToText(w.Description ?? ''),
    parent,
    ...(w.Experimental ? { experimental: true } : {}),
  };
  if (wirePath) wirePath.set(id, path);
  if (w.Present_When && inModule !== null) {
    pending.push({
      id,
      owner: w.Present_When.Owner,
      path: w.Present_When.Path,
      values: w.Present_When.Values,
    });
  }
  const kids = Object.entries(w.Children ?? {});
  switch (w.Kind) {
    case 'Boolean':
      nodes.set(id, {
        ...base,
        kind: 'boolean',
        ...(typeof w.Default === 'boolean' ? { default: w.Default } : {}),
      });
      return;
    case 'Discrete':
      nodes.set(id, {
        ...base,
        kind: 'discrete',
        options: w.Options ?? [],
        ...(typeof w.Default === 'string' ? { default: w.Default } : {}),
      });
      return;
    case 'Integer':
    case 'Float': {
      const d =
        typeof w.Default === 'number' ? w.Default : typeof w.Default === 'string' ? Number(w.Default) : NaN;
      nodes.set(id, {
        ...base,
        kind: w.Kind === 'Integer' ? 'integer' : 'float',
        min: w.Min ?? -Infinity,
        max: w.Max ?? Infinity,
        unit: w.Unit ?? '',
        ...(Number.isFinite(d) ? { default: d } : {}),
      });
      return;
    }
    case 'Float_Ratio':
      nodes.set(id, {
        ...base,
        kind: 'ratio',
        min: w.Min ?? -Infinity,
        max: w.Max ?? Infinity,
        ...(w.Default_Numerator !== undefined && w.Default_Denominator !== undefined
          ? { default: { numerator: w.Default_Numerator, denominator: w.Default_Denominator } }
          : {}),
      });
      return;
    case 'String':
      nodes.set(id, {
        ...base,
        kind: 'string',
        ...(typeof w.Default === 'string' ? { default: w.Default } : {}),
      });
      return;
    case 'Sequence':
    case 'Tabbed_Sequence': {
      const children = kids.map(([k]) => id + SEP + k);
      nodes.set(id, {
        ...base,
        kind: 'group',
        tabbed: w.Kind === 'Tabbed_Sequence' || w.Tabbed === true,
        children,
      });
      for (const [k, c] of kids)
        mapNode(nodes, id + SEP + k, k, id, c, inModule, wirePath, [...path, k], pending);
      return;
    }
    case 'Variant': {
      const children = kids.map(([k]) => id + SEP + k);
      nodes.set(id, {
        ...base,
        kind: 'variant',
        children,
        ...(typeof w.Default === 'string' ? { default: w.Default } : {}),
      });
      for (const [k, c] of kids) {
        mapNode(nodes, id + SEP + k, k, id, c, inModule, wirePath, [...path, 'Children', k], pending);
      }
      return;
    }
    default:
      nodes.set(id, { ...base, kind: 'unknown', rawKind: w.Kind });
  }
}

function buildFlat(schema: FlatConfigSchema, rawText?: string): PruntForm {
  const nodes = new Map<string, FormNode>();
  const roots: string[] = [];
  for (const [k, w] of Object.entries(schema)) {
    roots.push(k);
    mapNode(nodes, k, k, null, w, null, null, [], []);
  }
  const key = `flat:${hashText(rawText ?? JSON.stringify(schema))}`;
  return {
    api: 'flat',
    form: { nodes, roots, key },
    wirePath: new Map(),
    moduleVersions: {},
    configVersion: 0,
  };
}

function buildModule(schema: ModuleConfigSchema): PruntForm {
  const nodes = new Map<string, FormNode>();
  const roots: string[] = [];
  const wirePath = new Map<string, string[]>();
  const moduleVersions: Record<string, number> = {};
  const pending: Array<{ id: string; owner: string; path: string[]; values: unknown[] }> = [];
  for (const [m, mod] of Object.entries(schema.Config)) {
    roots.push(m);
    moduleVersions[m] = mod.Version;
    const props = Object.entries(mod.Config);
    nodes.set(m, {
      id: m,
      key: m,
      label: m,
      description: '',
      searchText: '',
      parent: null,
      kind: 'group',
      tabbed: false,
      children: props.map(([k]) => m + SEP + k),
    });
    wirePath.set(m, ['Config', m, 'Config']);
    for (const [k, w] of props) {
      mapNode(nodes, m + SEP + k, k, m, w, m, wirePath, ['Config', m, 'Config', k], pending);
    }
  }
  const key = `module:${schema['Prunt config version']}:${Object.entries(moduleVersions)
    .map(([m, v]) => `${m}=${v}`)
    .join(',')}`;
  const pf: PruntForm = {
    api: 'module',
    form: { nodes, roots, key },
    wirePath,
    moduleVersions,
    configVersion: schema['Prunt config version'],
  };
  // Present_When points at a value path inside its owner module: resolve it to a node id.
  for (const p of pending) {
    const target = moduleIdForPath(pf, ['Config', p.owner, 'Config', ...p.path]);
    const n = nodes.get(p.id);
    if (!n || !target) continue;
    const values = p.values.filter(
      (v): v is FormValue => typeof v === 'boolean' || typeof v === 'number' || typeof v === 'string',
    );
    const pw: PresentWhen = { field: target, values };
    nodes.set(p.id, { ...n, presentWhen: pw });
  }
  return pf;
}

// ---------------------------------------------------------------------------------------------
// Values

/** Server values → form values by node id. Values that do not fit their kind are left out (the default shows). */
export function readValues(pf: PruntForm, values: Record<string, unknown>): Record<string, FormValue> {
  const out: Record<string, FormValue> = {};
  const nodes = pf.form.nodes;
  if (pf.api === 'flat') {
    for (const [id, n] of nodes) {
      if (n.kind === 'group' || n.kind === 'unknown') continue;
      if (n.kind === 'ratio') {
        const num = values[id + SEP + 'Numerator'];
        const den = values[id + SEP + 'Denominator'];
        if (isNum(num) && isNum(den)) out[id] = { numerator: Number(num), denominator: Number(den) };
        continue;
      }
      const v = coerceLeaf(n.kind, values[id]);
      if (v !== undefined) out[id] = v;
    }
    return out;
  }
  const config = asObj(values['Config']);
  const walk = (id: string, v: unknown) => {
    const n = nodes.get(id);
    if (!n || v === undefined) return;
    switch (n.kind) {
      case 'group': {
        const o = asObj(v);
        for (const c of n.children) walk(c, o[nodes.get(c)?.key ?? '']);
        return;
      }
      case 'variant': {
        const o = asObj(v);
        if (typeof o['Selected'] === 'string') out[id] = o['Selected'];
        const ch = asObj(o['Children']);
        for (const c of n.children) walk(c, ch[nodes.get(c)?.key ?? '']);
        return;
      }
      case 'ratio': {
        const o = asObj(v);
        if (isNum(o['Numerator']) && isNum(o['Denominator'])) {
          out[id] = { numerator: Number(o['Numerator']), denominator: Number(o['Denominator']) };
        }
        return;
      }
      case 'unknown':
        return;
      default: {
        const x = coerceLeaf(n.kind, v);
        if (x !== undefined) out[id] = x;
      }
    }
  };
  for (const m of pf.form.roots) walk(m, asObj(config[m])['Config']);
  return out;
}

function coerceLeaf(kind: FormNode['kind'], v: unknown): FormValue | undefined {
  switch (kind) {
    case 'boolean':
      return typeof v === 'boolean' ? v : undefined;
    case 'integer':
    case 'float':
      return isNum(v) ? Number(v) : undefined;
    case 'discrete':
    case 'string':
    case 'variant':
      return typeof v === 'string' ? v : typeof v === 'number' ? String(v) : undefined;
    default:
      return undefined;
  }
}

function isNum(v: unknown): boolean {
  return (
    (typeof v === 'number' && Number.isFinite(v)) ||
    (typeof v === 'string' && v.trim() !== '' && Number.isFinite(Number(v)))
  );
}

function asObj(v: unknown): Record<string, unknown> {
  return v && typeof v === 'object' && !Array.isArray(v) ? (v as Record<string, unknown>) : {};
}

type WireLeaf = boolean | number | string;

function toWire(n: FormNode, v: FormValue): WireLeaf | { Numerator: number; Denominator: number } {
  if (n.kind === 'ratio' && typeof v === 'object') {
    return { Numerator: toNumber(v.numerator), Denominator: toNumber(v.denominator) };
  }
  if ((n.kind === 'integer' || n.kind === 'float') && typeof v !== 'object' && typeof v !== 'boolean')
    return toNumber(v);
  if (typeof v === 'object') return `${v.numerator}/${v.denominator}`;
  return v;
}

// ---------------------------------------------------------------------------------------------
// Patch

export type FlatPatch = Record<string, WireLeaf>;
export interface ModulePatch {
  'Prunt config version': number;
  Config: Record<string, { Version: number; Config: Record<string, unknown> }>;
}

/** The ids to send for these changes: a changed variant takes its whole subtree along. */
function idsToSend(pf: PruntForm, changes: readonly Change[]): Set<string> {
  const send = new Set<string>();
  const nodes = pf.form.nodes;
  const addSubtree = (id: string) => {
    const n = nodes.get(id);
    if (!n) return;
    if (n.kind !== 'group' && n.kind !== 'unknown') send.add(id);
    if (n.kind === 'group' || n.kind === 'variant') for (const c of n.children) addSubtree(c);
  };
  for (const c of changes) {
    send.add(c.id);
    if (c.node.kind === 'variant') addSubtree(c.id);
  }
  return send;
}

/**
 * Flat API: only the changed keys, plus every key under a variant whose selection changed (the
 * other choices' values are kept and sent, as the stock UI does).
 */
export function buildFlatPatch(
  pf: PruntForm,
  changes: readonly Change[],
  valueOf: (id: string) => FormValue | undefined,
): FlatPatch {
  const out: FlatPatch = {};
  for (const id of idsToSend(pf, changes)) {
    const n = pf.form.nodes.get(id);
    const v = valueOf(id);
    if (!n || v === undefined) continue;
    const w = toWire(n, v);
    if (typeof w === 'object') {
      out[id + SEP + 'Numerator'] = w.Numerator;
      out[id + SEP + 'Denominator'] = w.Denominator;
    } else out[id] = w;
  }
  return out;
}

/**
 * Module API: a partial values object with "Prunt config version" and the Version of every module
 * touched (the document requires both). A change inside a variant sends the whole top-most
 * variant: `{"Selected", "Children": {every choice}}` — non-selected children are present.
 */
export function buildModulePatch(
  pf: PruntForm,
  changes: readonly Change[],
  valueOf: (id: string) => FormValue | undefined,
): ModulePatch {
  const nodes = pf.form.nodes;
  const patch: ModulePatch = { 'Prunt config version': pf.configVersion, Config: {} };
  const anchors = new Set<string>();
  for (const c of changes) {
    let anchor = c.id;
    let p: string | null = c.id;
    while (p !== null) {
      const n = nodes.get(p);
      if (!n) break;
      if (n.kind === 'variant') anchor = p;
      p = n.parent;
    }
    anchors.add(anchor);
  }
  const full = (id: string): unknown => {
    const n = nodes.get(id);
    if (!n) return undefined;
    if (n.kind === 'group') {
      const o: Record<string, unknown> = {};
      for (const c of n.children) {
        const v = full(c);
        if (v !== undefined) o[nodes.get(c)?.key ?? c] = v;
      }
      return o;
    }
    if (n.kind === 'variant') {
      const ch: Record<string, unknown> = {};
      for (const c of n.children) {
        const v = full(c);
        if (v !== undefined) ch[nodes.get(c)?.key ?? c] = v;
      }
      return { Selected: valueOf(id), Children: ch };
    }
    if (n.kind === 'unknown') return undefined;
    const v = valueOf(id);
    return v === undefined ? undefined : toWire(n, v);
  };
  for (const id of anchors) {
    const path = pf.wirePath.get(id);
    if (!path || path.length < 4) continue;
    const module = path[1] as string;
    const mod = (patch.Config[module] ??= { Version: pf.moduleVersions[module] ?? 1, Config: {} });
    let cur: Record<string, unknown> = mod.Config;
    const rest = path.slice(3);
    for (let i = 0; i < rest.length - 1; i++) {
      const seg = rest[i] as string;
      const next = asObj(cur[seg]);
      cur[seg] = next;
      cur = next;
    }
    cur[rest[rest.length - 1] as string] = full(id);
  }
  return patch;
}

// ---------------------------------------------------------------------------------------------
// Errors

/** Module API value path → node id (the deepest node it reaches: a path may point at a group). */
export function moduleIdForPath(pf: PruntForm, path: readonly string[]): string | null {
  if (path[0] !== 'Config' || path.length < 2) return null;
  const module = path[1] as string;
  if (!pf.form.nodes.has(module)) return null;
  let id = module;
  let i = path[2] === 'Config' ? 3 : 2;
  for (; i < path.length; i++) {
    const seg = path[i] as string;
    const n = pf.form.nodes.get(id);
    if (!n) break;
    if (n.kind === 'variant' && (seg === 'Children' || seg === 'Selected')) continue;
    if (n.kind === 'ratio' && (seg === 'Numerator' || seg === 'Denominator')) continue;
    const next = id + SEP + seg;
    if (!pf.form.nodes.has(next)) break;
    id = next;
  }
  return id;
}

/** Flat API key → node id: exact, ratio parts, else the nearest existing group ("Kinematics$Maximum jerkk" → "Kinematics"). */
export function flatIdForKey(pf: PruntForm, key: string): string | null {
  if (pf.form.nodes.has(key)) return key;
  const m = /^(.*)\$(Numerator|Denominator)$/.exec(key);
  if (m && pf.form.nodes.has(m[1] as string)) return m[1] as string;
  const parts = key.split(SEP);
  for (let i = parts.length - 1; i > 0; i--) {
    const p = parts.slice(0, i).join(SEP);
    if (pf.form.nodes.has(p)) return p;
  }
  return null;
}

export interface PlacedError {
  id: string | null;
  message: string;
  /** The schema was violated: nothing was saved. */
  schemaError: boolean;
}

const SCHEMA_PREFIX = 'Data does not match schema';

export function placeErrors(pf: PruntForm, errors: readonly ConfigErrorWire[]): PlacedError[] {
  return errors.map((e) => {
    let id: string | null = null;
    if (e.Path && e.Path.length) id = moduleIdForPath(pf, e.Path);
    else if (e.Key !== undefined) id = flatIdForKey(pf, e.Key);
    const where = id ? '' : e.Key ? ` (at ${e.Key})` : e.Path ? ` (at ${e.Path.join(' › ')})` : '';
    return { id, message: e.Message + where, schemaError: e.Message.startsWith(SCHEMA_PREFIX) };
  });
}
