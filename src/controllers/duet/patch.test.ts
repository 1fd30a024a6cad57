import { describe, expect, it } from 'vitest';
import { fixtureJson, patchFiles } from './fixtures.test-util';
import {
  applyPatch,
  diffModel,
  patchBetween,
  isObject,
  jsonEqual,
  MAX_DEPTH,
  nestsDeeper,
  takeFullModel,
  type Json,
  type JsonObject,
} from './patch';
import { objectModelSchema } from './wire';

const base = (): JsonObject => fixtureJson('object-model/model_geminiv2.json');

/** Every value the patch sets must be readable at the same place in the result. */
function expectApplied(result: Json | undefined, patch: Json, path: string, inPlugins = false): void {
  if (isObject(patch)) {
    if (Object.keys(patch).length === 0) return; // "unchanged"
    expect(isObject(result), path).toBe(true);
    const r = result as JsonObject;
    for (const [k, v] of Object.entries(patch)) {
      if (!path && k === 'messages') continue;
      if (v === null && inPlugins) expect(k in r, `${path}.${k} deleted`).toBe(false);
      else expectApplied(r[k], v, `${path}.${k}`, !path && k === 'plugins');
    }
    return;
  }
  if (Array.isArray(patch)) {
    expect(Array.isArray(result), path).toBe(true);
    const r = result as Json[];
    expect(r.length, `${path} length`).toBe(patch.length);
    patch.forEach((item, i) => expectApplied(r[i], item, `${path}[${i}]`));
    return;
  }
  expect(result, path).toEqual(patch);
}

describe('applyPatch against every patch fixture', () => {
  for (const file of patchFiles()) {
    it(`${file}`, () => {
      const model = base();
      const before = structuredClone(model);
      const patch = fixtureJson(file);
      const { model: out, messages } = applyPatch(model, patch);
      expect(model).toEqual(before); // pure
      expectApplied(out, patch, '');
      expect(out['messages']).toEqual([]);
      expect(messages).toEqual(Array.isArray(patch['messages']) ? patch['messages'] : []);
      // The merged model still validates.
      const parsed = objectModelSchema.safeParse(out);
      expect(parsed.success, parsed.success ? '' : JSON.stringify(parsed.error.issues[0])).toBe(true);
      // The simulator's diff of the two models re-creates the same result.
      const d = diffModel(before, out);
      const again = d ? applyPatch(before, d).model : before;
      expect(jsonEqual(again, out)).toBe(true);
    });
  }
});

describe('patch rules', () => {
  it('merges a partial array item by index and keeps its siblings', () => {
    const m = base();
    const { model } = applyPatch(m, fixtureJson('patches/dsf-python/test_boards_2__boards-vin-partial.json'));
    const board = (model['boards'] as JsonObject[])[0]!;
    expect(board['vIn']).toEqual({ current: 42.5, min: 24, max: 24 });
    expect(board['name']).toBe('fly_geminiv2.0');
  });

  it('treats {} items as unchanged in a sparse array and takes the patch length', () => {
    let { model } = applyPatch(
      base(),
      fixtureJson('patches/dsf-python/test_http_endpoints_1__sbc-dsf-httpEndpoints-1.json'),
    );
    ({ model } = applyPatch(
      model,
      fixtureJson('patches/dsf-python/test_http_endpoints_2__sbc-dsf-httpEndpoints-2-sparse-array.json'),
    ));
    const eps = ((model['sbc'] as JsonObject)['dsf'] as JsonObject)['httpEndpoints'] as JsonObject[];
    expect(eps).toHaveLength(2);
    expect(eps[0]!['path']).toBe('getCmdList');
    expect(eps[1]!['path']).toBe('saveCmdList');
    // and a shorter array shrinks
    ({ model } = applyPatch(model, { sbc: { dsf: { httpEndpoints: [{}] } } }));
    expect(((model['sbc'] as JsonObject)['dsf'] as JsonObject)['httpEndpoints']).toHaveLength(1);
  });

  it('null array items are holes, null values set null', () => {
    const { model } = applyPatch(base(), {
      heat: { heaters: [{}, null] },
      state: { messageBox: null, logFile: null },
    });
    const heaters = (model['heat'] as JsonObject)['heaters'] as Json[];
    expect(heaters[1]).toBeNull();
    expect((heaters[0] as JsonObject)['max']).toBe(120);
    expect((model['state'] as JsonObject)['logFile']).toBeNull();
    expect('logFile' in (model['state'] as JsonObject)).toBe(true);
  });

  it('adds, updates and deletes plugins by key', () => {
    let { model } = applyPatch(base(), fixtureJson('patches/dsf-python/test_plugins_1__plugins-add.json'));
    expect(Object.keys(model['plugins'] as JsonObject)).toContain('ExecOnMcode');
    ({ model } = applyPatch(model, fixtureJson('patches/dsf-python/test_plugins_2__plugins-pid.json')));
    const p = (model['plugins'] as JsonObject)['ExecOnMcode'] as JsonObject;
    expect(p['pid']).toBe(1125);
    expect(p['author']).toBe('Loïc GRENON');
    ({ model } = applyPatch(
      model,
      fixtureJson('patches/dsf-python/test_plugins_3__plugins-remove-null.json'),
    ));
    expect(Object.keys(model['plugins'] as JsonObject).sort()).toEqual([
      'DuetPiManagementPlugin',
      'EndstopsMonitor',
    ]);
  });

  it('moves messages out of the model', () => {
    const r = applyPatch(base(), fixtureJson('patches/dsf-python/test_messages_1__messages-new.json'));
    expect(r.messages).toHaveLength(1);
    expect((r.messages[0] as JsonObject)['content']).toMatch(/will print in 0h 14m/);
    expect(r.model['messages']).toEqual([]);
    const full = takeFullModel({ ...base(), messages: [{ content: 'hello', type: 1, time: null }] });
    expect(full.messages).toHaveLength(1);
    expect(full.model['messages']).toEqual([]);
  });

  it('replaces kinematics when the type changes (no stale coreXY matrices on a delta)', () => {
    const { model } = applyPatch(
      base(),
      fixtureJson('patches/dsf-python/test_move_kinematics_1__move-kinematics-delta-minimal.json'),
    );
    const k = (model['move'] as JsonObject)['kinematics'] as JsonObject;
    expect(k).toEqual({ name: 'delta', deltaRadius: 123 });
    const { model: m2 } = applyPatch(
      base(),
      fixtureJson('patches/dsf-python/test_move_kinematics_2__move-kinematics-corexy.json'),
    );
    expect(((m2['move'] as JsonObject)['kinematics'] as JsonObject)['name']).toBe('coreXY');
  });

  it('replaces a filament monitor whose type changes', () => {
    let { model } = applyPatch(
      base(),
      fixtureJson('patches/dsf-python/test_sensors_filament_monitor_1__sensors-filamentMonitors-simple.json'),
    );
    ({ model } = applyPatch(
      model,
      fixtureJson('patches/dsf-python/test_sensors_filament_monitor_2__sensors-filamentMonitors-pulsed.json'),
    ));
    const fm = ((model['sensors'] as JsonObject)['filamentMonitors'] as JsonObject[])[0]!;
    expect(fm['type']).toBe('pulsed');
    expect(fm['configured']).toEqual({ mmPerPulse: 1, percentMax: 160, percentMin: 60, sampleDistance: 5 });
  });

  it('an empty object patch changes nothing', () => {
    const m = base();
    const { model } = applyPatch(m, fixtureJson('patches/dsf-python/test_user_sessions_1__sbc-empty.json'));
    expect(jsonEqual(model, m)).toBe(true);
  });
});

describe('diffModel', () => {
  it('returns null for equal models and a sparse patch for one changed heater', () => {
    const a = base();
    expect(diffModel(a, structuredClone(a))).toBeNull();
    const b = structuredClone(a);
    (((b['heat'] as JsonObject)['heaters'] as JsonObject[])[1] as JsonObject)['current'] = 25.5;
    expect(diffModel(a, b)).toEqual({ heat: { heaters: [{}, { current: 25.5 }] } });
  });
  it('sends removed plugins as null', () => {
    const a = base();
    const b = structuredClone(a);
    delete (b['plugins'] as JsonObject)['EndstopsMonitor'];
    expect(diffModel(a, b)).toEqual({ plugins: { EndstopsMonitor: null } });
  });
});

// ------------------------------------------------------------------------------------------
// diffModel against DSF's rules: a patch that takes one model to another, however many DSF
// patches lie between them (what the gateway sends a browser that missed some).

/** A small seeded PRNG (mulberry32): the same cases on every run, a seed to reproduce one. */
function rng(seed: number): () => number {
  let a = seed >>> 0;
  return () => {
    a = (a + 0x6d2b79f5) >>> 0;
    let t = a;
    t = Math.imul(t ^ (t >>> 15), t | 1);
    t ^= t + Math.imul(t ^ (t >>> 7), t | 61);
    return ((t ^ (t >>> 14)) >>> 0) / 4294967296;
  };
}

type Rand = () => number;
const int = (r: Rand, n: number) => Math.floor(r() * n);
const pick = <T>(r: Rand, xs: readonly T[]): T => xs[int(r, xs.length)] as T;
const chance = (r: Rand, p: number) => r() < p;

/** DSF's model is typed: every object of a class has the same keys (only values change). */
const heater = (r: Rand): JsonObject => ({
  active: int(r, 250),
  standby: int(r, 200),
  current: Math.round(r() * 2500) / 10,
  state: pick(r, ['off', 'standby', 'active', 'fault']),
  sensor: int(r, 4),
  monitors: [{ action: int(r, 3), condition: pick(r, ['tooHigh', 'tooLow']), limit: int(r, 300) }],
});
const axis = (r: Rand, letter: string): JsonObject => ({
  letter,
  homed: chance(r, 0.5),
  userPosition: Math.round(r() * 3000) / 10,
  min: 0,
  max: int(r, 400),
});
const KINEMATICS: Record<string, (r: Rand) => JsonObject> = {
  coreXY: (r) => ({
    name: 'coreXY',
    forwardMatrix: [
      [0.5, 0.5, int(r, 2)],
      [0.5, -0.5, 0],
    ],
    segmentation: { segmentsPerSec: int(r, 100), minSegmentLength: 0.2 },
  }),
  delta: (r) => ({
    name: 'delta',
    deltaRadius: int(r, 200),
    towers: [0, 1, 2].map(() => ({ angleCorrection: r(), diagonal: 215, xPos: r(), yPos: r() })),
  }),
  cartesian: (r) => ({
    name: 'cartesian',
    tiltCorrection: { correctionFactor: r(), lastCorrections: [r()] },
  }),
};
const MONITORS: Record<string, (r: Rand) => JsonObject> = {
  simple: (r) => ({ type: 'simple', enabled: chance(r, 0.5), status: 'ok', filamentPresent: chance(r, 0.5) }),
  pulsed: (r) => ({
    type: 'pulsed',
    enabled: true,
    status: 'ok',
    calibrated: chance(r, 0.5) ? null : { mmPerPulse: r(), percentMax: 160, percentMin: 60 },
    configured: { mmPerPulse: r(), percentMax: 160, percentMin: 60, sampleDistance: 5 },
  }),
  laser: (r) => ({ type: 'laser', enabled: true, status: 'ok', calibrated: { sensivity: r() } }),
};
const plugin = (r: Rand, id: string): JsonObject => ({
  id,
  name: id,
  pid: chance(r, 0.3) ? -1 : int(r, 5000),
  data: { count: int(r, 10) },
  sbcPermissions: ['commandExecution'],
});
const layer = (r: Rand, n: number): JsonObject => ({
  duration: r() * 100,
  height: 0.2 * n,
  temperatures: [int(r, 250)],
});
const messageBox = (r: Rand): JsonObject => ({ mode: int(r, 8), seq: int(r, 100), title: 'T', message: 'M' });

function startModel(r: Rand): JsonObject {
  return {
    state: { status: 'idle', upTime: 0, messageBox: null },
    heat: { heaters: [heater(r), heater(r), null], bedHeaters: [0, -1] },
    move: {
      axes: ['X', 'Y', 'Z'].map((l) => axis(r, l)),
      kinematics: (KINEMATICS['coreXY'] as (r: Rand) => JsonObject)(r),
    },
    sensors: { filamentMonitors: [(MONITORS['simple'] as (r: Rand) => JsonObject)(r)] },
    plugins: { A: plugin(r, 'A'), B: plugin(r, 'B') },
    job: { file: { fileName: null, size: 0 }, layers: [] },
    global: { g: 1 },
  };
}

const arr = (v: Json | undefined): Json[] => (Array.isArray(v) ? v : []);
const obj = (v: Json | undefined): JsonObject => (isObject(v) ? v : {});

/** A sparse array patch as DSF sends it: `{}` (or `null`) for unchanged items, a change at one. */
function sparse(items: Json[], at: number, change: Json): Json[] {
  return items.map((x, i) => (i === at ? change : x === null ? null : {}));
}

/** One patch DSF could send for `m` (one to three changes), with a message now and then. */
function dsfPatch(r: Rand, m: JsonObject): JsonObject {
  const p: JsonObject = {};
  const heaters = arr(obj(m['heat'])['heaters']);
  const monitors = arr(obj(m['sensors'])['filamentMonitors']);
  const layers = arr(obj(m['job'])['layers']);
  const plugins = obj(m['plugins']);
  for (let n = 1 + int(r, 3); n > 0; n--) {
    switch (int(r, 14)) {
      case 0:
        p['state'] = {
          status: pick(r, ['idle', 'processing', 'paused', 'halted', 'busy']),
          upTime: int(r, 1e6),
        };
        break;
      case 1: {
        // one heater changes a value (sparse array)
        const i = int(r, heaters.length + 1);
        if (i < heaters.length && heaters[i] !== null)
          p['heat'] = { heaters: sparse(heaters, i, { current: Math.round(r() * 2500) / 10 }) };
        break;
      }
      case 2:
        // heaters grow (new items whole) or shrink
        p['heat'] = {
          heaters: chance(r, 0.5)
            ? [...heaters.map((h) => (h === null ? null : {})), heater(r)]
            : heaters.slice(0, int(r, heaters.length)).map((h) => (h === null ? null : {})),
        };
        break;
      case 3: {
        // a hole, or a hole filled (whole)
        const i = int(r, Math.max(1, heaters.length));
        if (i < heaters.length)
          p['heat'] = { heaters: sparse(heaters, i, heaters[i] === null ? heater(r) : null) };
        break;
      }
      case 4:
        // kinematics: a new type (whole) or a value of the same type
        p['move'] = chance(r, 0.5)
          ? { kinematics: (KINEMATICS[pick(r, Object.keys(KINEMATICS))] as (r: Rand) => JsonObject)(r) }
          : { axes: [{}, { userPosition: r() * 100 }] };
        break;
      case 5: {
        const k = obj(obj(m['move'])['kinematics']);
        if (k['name'] === 'delta') p['move'] = { kinematics: { deltaRadius: int(r, 300) } };
        if (k['name'] === 'coreXY')
          p['move'] = {
            kinematics: {
              forwardMatrix: [
                [0.5, 0.5, 1],
                [0.5, -0.5, int(r, 3)],
              ],
            },
          };
        break;
      }
      case 6:
        // a filament monitor changes type (whole item) or one value
        p['sensors'] = {
          filamentMonitors: chance(r, 0.5)
            ? [(MONITORS[pick(r, Object.keys(MONITORS))] as (r: Rand) => JsonObject)(r)]
            : monitors.map(() => ({ enabled: chance(r, 0.5) })),
        };
        break;
      case 7: {
        // plugins: add, change, delete (null)
        const id = pick(r, ['A', 'B', 'C', 'D']);
        const pl: JsonObject = {};
        if (!(id in plugins)) pl[id] = plugin(r, id);
        else pl[id] = chance(r, 0.5) ? null : { pid: int(r, 9000), data: { count: int(r, 9) } };
        p['plugins'] = pl;
        break;
      }
      case 8:
        // layers: one more (whole), or the job restarts (none), or a new job (some)
        p['job'] = {
          layers: chance(r, 0.6)
            ? [...layers.map(() => ({})), layer(r, layers.length)]
            : chance(r, 0.5)
              ? []
              : [layer(r, 0), layer(r, 1)],
        };
        break;
      case 9:
        p['job'] = {
          file: { fileName: chance(r, 0.5) ? null : `0:/gcodes/part${int(r, 5)}.gcode`, size: int(r, 1e6) },
        };
        break;
      case 10:
        p['state'] = { messageBox: chance(r, 0.5) ? null : messageBox(r) };
        break;
      case 11:
        // a message, or none (`{"messages":[]}`, test_messages_2)
        p['messages'] = chance(r, 0.3) ? [] : [{ content: `m${int(r, 100)}`, type: int(r, 3), time: null }];
        break;
      case 12:
        p['global'] = {
          g: chance(r, 0.2) ? null : int(r, 5),
          [`v${int(r, 3)}`]: pick(r, [1, 'x', true, [1, 2], { a: 1 }]),
        };
        break;
      default:
        // an array of arrays, whole
        p['move'] = {
          ...obj(p['move']),
          compensation: {
            grid: [
              [int(r, 3), 1],
              [2, int(r, 3)],
            ],
          },
        };
    }
  }
  return p;
}

/** Applies `patch` to `from` through JSON (as a browser gets it) and compares with `to`. */
function roundTrip(from: JsonObject, to: JsonObject, events: Json[]) {
  const frame = JSON.parse(JSON.stringify(patchBetween(from, to, events))) as JsonObject;
  return applyPatch(from, frame);
}

describe('diffModel property: DSF-style patch sequences', () => {
  for (let seed = 1; seed <= 40; seed++) {
    it(`seed ${seed}: one patch takes any model of a sequence to any later one`, () => {
      const r = rng(seed);
      const models: JsonObject[] = [startModel(r)];
      const carried: Json[][] = [[]];
      for (let i = 0; i < 20; i++) {
        const res = applyPatch(
          models[models.length - 1] as JsonObject,
          dsfPatch(r, models[models.length - 1] as JsonObject),
        );
        models.push(res.model);
        carried.push(res.messages);
      }
      for (let i = 0; i < models.length; i++) {
        for (let j = i; j < models.length; j++) {
          const from = models[i] as JsonObject;
          const to = models[j] as JsonObject;
          const events = carried.slice(i + 1, j + 1).flat();
          const { model, messages } = roundTrip(from, to, events);
          expect(model, `seed ${seed}, ${i} → ${j}`).toEqual(to);
          expect(messages).toEqual(events);
        }
      }
    });
  }
});

/** `got` has everything `want` has; keys `want` lacks are null in `got` (the documented limit). */
function expectCoveredWithNulls(got: Json | undefined, want: Json, path: string): void {
  if (isObject(want)) {
    expect(isObject(got), path).toBe(true);
    const g = got as JsonObject;
    for (const [k, v] of Object.entries(want)) expectCoveredWithNulls(g[k], v, `${path}.${k}`);
    for (const k of Object.keys(g)) if (!(k in want)) expect(g[k], `${path}.${k} (vanished)`).toBeNull();
    return;
  }
  if (Array.isArray(want)) {
    expect(Array.isArray(got), path).toBe(true);
    const g = got as Json[];
    expect(g.length, `${path} length`).toBe(want.length);
    want.forEach((w, i) => expectCoveredWithNulls(g[i], w, `${path}[${i}]`));
    return;
  }
  expect(got, path).toEqual(want);
}

/** Any value at all (objects with any keys, arrays, scalars), never a `{}` array item. */
function anyValue(r: Rand, depth: number): Json {
  const k = int(r, depth > 2 ? 4 : 7);
  if (k === 0) return null;
  if (k === 1) return int(r, 10);
  if (k === 2) return pick(r, ['a', 'b', '']);
  if (k === 3) return chance(r, 0.5);
  if (k === 4) return Array.from({ length: int(r, 3) }, () => anyItem(r, depth + 1));
  const o: JsonObject = {};
  for (let n = 1 + int(r, 3); n > 0; n--)
    o[pick(r, ['p', 'q', 's', 'name', 'type'])] = anyValue(r, depth + 1);
  return o;
}
function anyItem(r: Rand, depth: number): Json {
  const v = anyValue(r, depth);
  return isObject(v) && Object.keys(v).length === 0 ? { p: 1 } : v;
}
function anyPatch(r: Rand): JsonObject {
  const p: JsonObject = {};
  const top = pick(r, ['x', 'y', 'plugins', 'move', 'sensors']);
  if (top === 'move') p['move'] = { kinematics: anyValue(r, 1) };
  else if (top === 'sensors')
    p['sensors'] = { filamentMonitors: Array.from({ length: int(r, 3) }, () => anyItem(r, 1)) };
  else p[top] = anyValue(r, 0);
  return p;
}

describe('diffModel property: arbitrary patches', () => {
  for (let seed = 100; seed < 160; seed++) {
    it(`seed ${seed}: exact, or a vanished key left as null (the documented limit)`, () => {
      const r = rng(seed);
      let model: JsonObject = { x: 1 };
      const models = [model];
      for (let i = 0; i < 20; i++) {
        model = applyPatch(model, anyPatch(r)).model;
        models.push(model);
      }
      for (let i = 0; i < models.length; i += 3) {
        for (let j = i; j < models.length; j += 2) {
          const { model: got } = roundTrip(models[i] as JsonObject, models[j] as JsonObject, []);
          expectCoveredWithNulls(got, models[j] as JsonObject, `${i} → ${j}`);
        }
      }
    });
  }
});

describe('diffModel by hand', () => {
  it('skips subtrees the two models share without looking into them (structural sharing)', () => {
    const untouchable = new Proxy<JsonObject>(
      {},
      {
        get: () => {
          throw new Error('walked a shared subtree');
        },
        ownKeys: () => {
          throw new Error('walked a shared subtree');
        },
      },
    );
    const from: JsonObject = { big: untouchable, state: { status: 'idle', upTime: 1 } };
    const to = applyPatch(from, { state: { upTime: 2 } }).model;
    expect(to['big']).toBe(untouchable);
    expect(diffModel(from, to)).toEqual({ state: { upTime: 2 } });
    expect(diffModel(to, to)).toBeNull();
  });

  it('sends a kinematics of a new type whole, so the old type leaves nothing behind', () => {
    const from = applyPatch(base(), {}).model;
    const to = applyPatch(
      from,
      fixtureJson('patches/dsf-python/test_move_kinematics_1__move-kinematics-delta-minimal.json'),
    ).model;
    expect(diffModel(from, to)).toEqual({ move: { kinematics: { name: 'delta', deltaRadius: 123 } } });
    expect(applyPatch(from, diffModel(from, to) as JsonObject).model).toEqual(to);
  });

  it('sends a filament monitor whose type changed whole, inside a sparse array', () => {
    let from = applyPatch(
      base(),
      fixtureJson('patches/dsf-python/test_sensors_filament_monitor_1__sensors-filamentMonitors-simple.json'),
    ).model;
    from = applyPatch(from, {
      sensors: { filamentMonitors: [{}, { type: 'simple', enabled: false }] },
    }).model;
    const to = applyPatch(from, {
      sensors: { filamentMonitors: [{}, { type: 'laser', enabled: true }] },
    }).model;
    expect(diffModel(from, to)).toEqual({
      sensors: { filamentMonitors: [{}, { type: 'laser', enabled: true }] },
    });
  });

  it('deletes plugins with null, grows and shrinks arrays by their length', () => {
    const from: JsonObject = {
      plugins: { A: { id: 'A' }, B: { id: 'B' } },
      heat: { heaters: [{ c: 1 }, { c: 2 }] },
    };
    const to: JsonObject = { plugins: { A: { id: 'A' } }, heat: { heaters: [{ c: 1 }] } };
    expect(diffModel(from, to)).toEqual({ plugins: { B: null }, heat: { heaters: [{}] } });
    const grown: JsonObject = {
      plugins: from['plugins'] as JsonObject,
      heat: { heaters: [{ c: 1 }, { c: 2 }, null, { c: 4 }] },
    };
    expect(diffModel(from, grown)).toEqual({ heat: { heaters: [{}, {}, null, { c: 4 }] } });
  });

  it('sends arrays inside arrays item by item (an inner {} would read "unchanged")', () => {
    const from: JsonObject = { m: [[{ a: 1 }, 1], [2]] };
    const to: JsonObject = { m: [[{ a: 1 }, 3], [2]] };
    const d = diffModel(from, to) as JsonObject;
    expect(d).toEqual({ m: [[{}, 3], [2]] });
    expect(applyPatch(from, d).model).toEqual(to);
  });

  it('carries events as messages, and the model keeps messages: [] once it has seen any', () => {
    const from: JsonObject = { state: { status: 'idle' } };
    const r = applyPatch(from, fixtureJson('patches/dsf-python/test_messages_1__messages-new.json'));
    const frame = patchBetween(from, r.model, r.messages);
    expect(frame).toEqual({ messages: r.messages });
    expect(applyPatch(from, frame).model).toEqual(r.model);
    // no events: the key is still sent the first time, so the model gains `messages: []`
    expect(patchBetween(from, r.model, [])).toEqual({ messages: [] });
    expect(patchBetween(r.model, r.model, [])).toEqual({});
  });

  it('documents its limit: a key DSF cannot remove is sent as null', () => {
    // an array that shrank and grew again with another item, and an A → B → A kinematics
    const from: JsonObject = { a: [{ p: 1, q: 2 }], move: { kinematics: { name: 'delta', r: 1, t: 2 } } };
    const to: JsonObject = { a: [{ p: 1 }], move: { kinematics: { name: 'delta', s: 3 } } };
    const d = diffModel(from, to) as JsonObject;
    expect(d).toEqual({ a: [{ q: null }], move: { kinematics: { r: null, t: null, s: 3 } } });
    expect(applyPatch(from, d).model).toEqual({
      a: [{ p: 1, q: null }],
      move: { kinematics: { name: 'delta', r: null, t: null, s: 3 } },
    });
  });

  it('treats inherited names as ordinary keys', () => {
    const from = JSON.parse('{"constructor":1,"toString":{"a":1}}') as JsonObject;
    const to = JSON.parse('{"constructor":2,"toString":{"a":1},"valueOf":3}') as JsonObject;
    expect(diffModel(from, to)).toEqual({ constructor: 2, valueOf: 3 });
    expect(diffModel({}, { constructor: { a: 1 } })).toEqual({ constructor: { a: 1 } });
  });
});

describe('applyPatch against hostile frames (issue 15)', () => {
  it('refuses a frame nested deeper than MAX_DEPTH whole, and takes one just within it', () => {
    const from = base();
    const nest = (depth: number): string => `${'{"a":'.repeat(depth)}1${'}'.repeat(depth)}`;
    for (const depth of [MAX_DEPTH, 20_000]) {
      const patch = JSON.parse(`{"plugins":{"p":${nest(depth - 2)}}}`) as JsonObject;
      const r = applyPatch(from, patch);
      if (depth === MAX_DEPTH) {
        expect(r.refused).toBeNull();
        expect(nestsDeeper(r.model, MAX_DEPTH)).toBe(false);
      } else {
        expect(r.refused).toMatch(/nested deeper/);
        expect(r.model).toBe(from);
        expect(r.messages).toEqual([]);
      }
    }
    const arrays = JSON.parse(`{"heat":${'['.repeat(20_000)}${']'.repeat(20_000)}}`) as JsonObject;
    expect(applyPatch(from, arrays).refused).toMatch(/nested deeper/);
    expect(takeFullModel(arrays).refused).toMatch(/nested deeper/);
  });

  it('never merges __proto__, constructor or prototype, at any depth, in objects or array items', () => {
    const patch = JSON.parse(
      '{"__proto__":{"polluted":1},"constructor":{"prototype":{"x":1}},"prototype":1,' +
        '"heat":{"__proto__":{"a":1},"heaters":[{"__proto__":{"b":1},"current":5}]},' +
        '"plugins":{"__proto__":null,"P":{"constructor":2,"id":"P"}}}',
    ) as JsonObject;
    const { model } = applyPatch(base(), patch);
    const heat = model['heat'] as JsonObject;
    const heater = (heat['heaters'] as JsonObject[])[0] as JsonObject;
    for (const o of [model, heat, heater, (model['plugins'] as JsonObject)['P'] as JsonObject]) {
      expect(Object.getPrototypeOf(o)).toBe(Object.prototype);
      for (const k of ['__proto__', 'constructor', 'prototype']) expect(Object.hasOwn(o, k), k).toBe(false);
    }
    expect(heater['current']).toBe(5);
    expect(({} as Record<string, unknown>)['polluted']).toBeUndefined();
  });

  it('diffModel never turns a key into a prototype either', () => {
    const to = JSON.parse('{"a":{"__proto__":{"x":1}}}') as JsonObject;
    const d = diffModel({ a: { y: 1 } }, to) as JsonObject;
    expect(Object.getPrototypeOf(d['a'])).toBe(Object.prototype);
    expect(JSON.stringify(d)).toBe('{"a":{"__proto__":{"x":1},"y":null}}');
  });
});
