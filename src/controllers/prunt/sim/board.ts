import type { WireNode } from '../wire';
type Board3Texts = typeof import('./data/board3');

/**
 * The simulated board: the exact Board 3 flat schema (fixtures/prunt/config-schema.json), and the
 * module-API schema derived from it. The derivation and the extra "Smart Plug" module are the
 * simulator's assumptions (no v2026 config schema exists in the fixtures, see SOURCES.md):
 * - each top-level section becomes one module of the same name with Version 1, holding the
 *   section as its single property — the shape of the real Fans module
 *   (`{"Fans":{"Version":1,"Config":{"Fans":{…}}}}` in v2026/config-values.fans-fragment.json);
 * - `Tabbed_Sequence` → `Sequence` with `"Tabbed": true`; defaults come from the first-start
 *   values (config-values-defaults.json), as the document's `Default` fields;
 * - the "Smart Plug" module exists only on the module API and exercises the newer schema
 *   features: `String`, `Present_When` and `Experimental` (names from html/src/ws.ts Smart_Plug).
 */

export type FlatSchema = Record<string, WireNode>;
export type FlatValues = Record<string, boolean | number | string>;

let texts: Board3Texts | null = null;
let loading: Promise<void> | null = null;
let cache: { schema: FlatSchema; values: FlatValues; defaults: FlatValues } | null = null;

/**
 * The board data (≈370 kB of JSON text) is loaded on demand, in its own chunk: the console's
 * main bundle does not carry it, only pages that run a simulated Prunt load it.
 */
export function loadBoard3(): Promise<void> {
  loading ??= import('./data/board3').then((m) => {
    texts = m;
  });
  return loading;
}

export function board3Texts(): Board3Texts {
  if (!texts) throw new Error('Board 3 data is not loaded yet: await loadBoard3() first');
  return texts;
}

/** Parsed once per process (the simulator may be created many times in tests). */
export function board3(): { schema: FlatSchema; values: FlatValues; defaults: FlatValues } {
  if (!cache) {
    const t = board3Texts();
    cache = {
      schema: JSON.parse(t.CONFIG_SCHEMA_TEXT) as FlatSchema,
      values: (JSON.parse(t.CONFIG_VALUES_TEXT) as { Values: FlatValues }).Values,
      defaults: (JSON.parse(t.CONFIG_DEFAULTS_TEXT) as { Values: FlatValues }).Values,
    };
  }
  return cache;
}

export function board3StatusSchema(): Record<string, string[]> {
  return JSON.parse(board3Texts().STATUS_SCHEMA_TEXT) as Record<string, string[]>;
}

export const SMART_PLUG_SECTION = 'Smart plug';
export const SMART_PLUG_MODULE = 'Smart Plug';

export const SMART_PLUG_SCHEMA: WireNode = {
  Kind: 'Sequence',
  Description: '<p>A network smart plug that powers the machine (simulated module).</p>',
  Children: {
    Enabled: {
      Kind: 'Boolean',
      Description: '<p>Control the machine power through a smart plug.</p>',
      Default: false,
    },
    Host: {
      Kind: 'String',
      Description: '<p>Host name or address of the plug.</p>',
      Default: 'plug.local',
      Present_When: { Owner: SMART_PLUG_MODULE, Path: [SMART_PLUG_SECTION, 'Enabled'], Values: [true] },
    },
    Provider: {
      Kind: 'Discrete',
      Description: '<p>Which kind of plug it is.</p>',
      Options: ['Tasmota', 'Shelly'],
      Default: 'Tasmota',
      Present_When: { Owner: SMART_PLUG_MODULE, Path: [SMART_PLUG_SECTION, 'Enabled'], Values: [true] },
    },
    'Watchdog seconds': {
      Kind: 'Integer',
      Description: '<p>Switch the plug off when the server stops answering for this long (0: never).</p>',
      Min: 0,
      Max: 3600,
      Unit: 's',
      Default: 0,
      Experimental: true,
    },
  },
};

export const SMART_PLUG_DEFAULTS: FlatValues = {
  'Smart plug$Enabled': false,
  'Smart plug$Host': 'plug.local',
  'Smart plug$Provider': 'Tasmota',
  'Smart plug$Watchdog seconds': 0,
};

/** Section → module name on the module API. */
export function moduleOf(section: string): string {
  return section === SMART_PLUG_SECTION ? SMART_PLUG_MODULE : section;
}

export function sectionOf(module: string): string {
  return module === SMART_PLUG_MODULE ? SMART_PLUG_SECTION : module;
}

function toModuleNode(n: WireNode, key: string, defaults: FlatValues): WireNode {
  const out: WireNode = { Kind: n.Kind, Description: n.Description };
  for (const k of ['Min', 'Max', 'Unit', 'Options', 'Experimental', 'Present_When'] as const) {
    if (n[k] !== undefined) (out as unknown as Record<string, unknown>)[k] = n[k];
  }
  if (n.Kind === 'Tabbed_Sequence' || n.Kind === 'Sequence') {
    out.Kind = 'Sequence';
    out.Tabbed = n.Kind === 'Tabbed_Sequence';
  }
  if (n.Children) {
    out.Children = {};
    for (const [k, c] of Object.entries(n.Children))
      out.Children[k] = toModuleNode(c, `${key}$${k}`, defaults);
  }
  if (n.Kind === 'Float_Ratio') {
    out.Default_Numerator = Number(defaults[`${key}$Numerator`] ?? 1);
    out.Default_Denominator = Number(defaults[`${key}$Denominator`] ?? 1);
  } else if (n.Kind !== 'Sequence' && n.Kind !== 'Tabbed_Sequence') {
    const d = n.Default ?? defaults[key];
    if (d !== undefined) out.Default = d;
  }
  return out;
}

/** The full flat schema the simulator validates against (the module API adds the Smart Plug section). */
export function simFlatSchema(api: 'module' | 'flat'): FlatSchema {
  const s = board3().schema;
  return api === 'module' ? { ...s, [SMART_PLUG_SECTION]: SMART_PLUG_SCHEMA } : s;
}

export function moduleSchema(): unknown {
  const { defaults } = board3();
  const all = { ...defaults, ...SMART_PLUG_DEFAULTS };
  const Config: Record<string, unknown> = {};
  for (const [section, n] of Object.entries(simFlatSchema('module'))) {
    Config[moduleOf(section)] = { Version: 1, Config: { [section]: toModuleNode(n, section, all) } };
  }
  return { 'Prunt config version': 1, Config };
}

/** Flat values → module values object (`{"Prunt config version":1,"Config":{…}}`). */
export function toModuleValues(values: FlatValues): unknown {
  const schema = simFlatSchema('module');
  const build = (n: WireNode, key: string): unknown => {
    switch (n.Kind) {
      case 'Sequence':
      case 'Tabbed_Sequence': {
        const o: Record<string, unknown> = {};
        for (const [k, c] of Object.entries(n.Children ?? {})) o[k] = build(c, `${key}$${k}`);
        return o;
      }
      case 'Variant': {
        const ch: Record<string, unknown> = {};
        for (const [k, c] of Object.entries(n.Children ?? {})) ch[k] = build(c, `${key}$${k}`);
        return { Selected: values[key], Children: ch };
      }
      case 'Float_Ratio':
        return { Numerator: values[`${key}$Numerator`], Denominator: values[`${key}$Denominator`] };
      default:
        return values[key];
    }
  };
  const Config: Record<string, unknown> = {};
  for (const [section, n] of Object.entries(schema)) {
    Config[moduleOf(section)] = { Version: 1, Config: { [section]: build(n, section) } };
  }
  return { 'Prunt config version': 1, Config };
}

/** Flat key → module error path (`["Config",module,"Config",section,…]`, "Children"/"Selected" where variants are). */
export function modulePathOf(key: string): string[] {
  const schema = simFlatSchema('module');
  const parts = key.split('$');
  const section = parts[0] ?? '';
  const path = ['Config', moduleOf(section), 'Config', section];
  let n: WireNode | undefined = schema[section];
  for (let i = 1; i < parts.length; i++) {
    const seg = parts[i] as string;
    if (n?.Kind === 'Variant') path.push('Children');
    path.push(seg);
    n = n?.Children?.[seg];
  }
  if (n?.Kind === 'Variant') path.push('Selected');
  return path;
}
