import { describe, expect, it } from 'vitest';
import { fixtureJson, patchFiles } from './fixtures.test-util';
import {
  applyPatch,
  diffModel,
  isObject,
  jsonEqual,
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
