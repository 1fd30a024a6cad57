import { describe, expect, it } from 'vitest';
import { fixtureJson, patchFiles } from './fixtures.test-util';
import { DuetModel } from './model';
import { applyPatch } from './patch';
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

  it('an invalid patch is a protocol error; the next frame is parsed whole again', () => {
    const m = new DuetModel();
    expect(m.full(base()).ok).toBe(true);
    const bad = m.patch({ state: { status: null } });
    expect(bad.ok).toBe(false);
    if (!bad.ok) expect(bad.error.message).toMatch(/object model\) at "state\.status"/);
    expect(m.current).toBeNull();
    const good = m.patch({ state: { status: 'idle' } });
    expect(good.ok && good.model.state.status).toBe('idle');
  });

  it('hands back the messages of a frame and never keeps them', () => {
    const m = new DuetModel();
    m.full(base());
    const r = m.patch({ messages: [{ content: 'hello', type: 0, time: null }] });
    expect(r.messages).toEqual([{ content: 'hello', type: 0, time: null }]);
    expect(r.ok && r.model['messages']).toEqual([]);
  });
});
