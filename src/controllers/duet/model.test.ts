import { describe, expect, it } from 'vitest';
import { fixtureJson, patchFiles } from './fixtures.test-util';
import { DuetModel } from './model';
import { applyPatch, type JsonObject } from './patch';
import { objectModelSchema } from './wire';

const base = () => fixtureJson('object-model/model_geminiv2.json');

describe('DuetModel: patches validated part by part', () => {
  for (const file of patchFiles()) {
    it(`${file}: the same model as a whole parse, untouched parts kept`, () => {
      const m = new DuetModel();
      const full = m.full(base());
      if (!full.ok) throw full.error;
      const patch = fixtureJson(file);
      const r = m.patch(patch);
      if (!r.ok) throw r.error;
      // What a whole parse of the merged model gives (the old way, every frame).
      const whole = objectModelSchema.parse(applyPatch(base(), patch).model);
      expect(r.model).toEqual(whole);
      for (const key of Object.keys(full.model)) {
        if (key in patch) continue;
        expect(r.model[key], key).toBe(full.model[key]);
      }
    });
  }

  it('a patch that would make a valid model invalid is a protocol error and dropped: the last valid model stays', () => {
    const m = new DuetModel();
    const full = m.full(base());
    if (!full.ok) throw full.error;
    const bad = m.patch({ state: { status: null }, heat: { heaters: [{ current: 99 }] } });
    expect(bad.ok).toBe(false);
    if (!bad.ok) {
      expect(bad.error.message).toMatch(/object model\) at "state\.status"/);
      expect(bad.dropped).toBe(true);
    }
    // Nothing of the dropped patch was merged (not even its valid part).
    expect(m.current).toBe(full.model);
    const good = m.patch({ state: { status: 'idle' } });
    expect(good.ok && good.model.state.status).toBe('idle');
    expect(good.ok && good.model.heat).toBe(full.model.heat);
  });

  it('over a model that is already invalid, patches merge until it is valid again (not dropped)', () => {
    const m = new DuetModel();
    const broken = m.full({ ...base(), state: { ...(base()['state'] as JsonObject), status: null } });
    expect(broken.ok).toBe(false);
    if (!broken.ok) expect(broken.dropped).toBe(false);
    expect(m.current).toBeNull();
    const still = m.patch({ heat: { heaters: [{ current: 99 }] } });
    expect(!still.ok && still.dropped).toBe(false);
    const good = m.patch({ state: { status: 'idle' } });
    expect(good.ok && good.model.heat.heaters[0]?.current).toBe(99);
  });

  it('a frame nested deeper than MAX_DEPTH is refused whole, without recursion', () => {
    const m = new DuetModel();
    const full = m.full(base());
    if (!full.ok) throw full.error;
    const deep = JSON.parse(`{"sensors":${'['.repeat(50_000)}1${']'.repeat(50_000)}}`) as JsonObject;
    const r = m.patch(deep);
    expect(r.ok).toBe(false);
    if (!r.ok) {
      expect(r.dropped).toBe(true);
      expect(r.error.kind).toBe('protocol');
      expect(r.error.message).toMatch(/nested deeper than 64/);
    }
    expect(m.current).toBe(full.model);
    const whole = new DuetModel().full(deep);
    expect(whole.ok).toBe(false);
  });

  it('never takes __proto__, constructor or prototype from a frame', () => {
    const m = new DuetModel();
    m.full(base());
    const frame = JSON.parse(
      '{"__proto__":{"polluted":1},"constructor":{"x":1},"prototype":2,"state":{"status":"idle","__proto__":{"isAdmin":true}}}',
    ) as JsonObject;
    const r = m.patch(frame);
    if (!r.ok) throw r.error;
    expect(Object.getPrototypeOf(r.model)).toBe(Object.prototype);
    expect(Object.getPrototypeOf(r.model.state)).toBe(Object.prototype);
    expect(Object.hasOwn(r.model, 'constructor') || Object.hasOwn(r.model, 'prototype')).toBe(false);
    expect(r.model.state.status).toBe('idle');
  });

  it('hands back the messages of a frame and never keeps them', () => {
    const m = new DuetModel();
    m.full(base());
    const r = m.patch({ messages: [{ content: 'hello', type: 0, time: null }] });
    expect(r.messages).toEqual([{ content: 'hello', type: 0, time: null }]);
    expect(r.ok && r.model['messages']).toEqual([]);
  });
});
