/**
 * Prunt Board 3 config form (682 settings): median time to build the form model from the
 * schema text, to load the values, and to apply one edit; and how many field subscribers
 * would re-render for one edit (each field selects its own value: the answer should be 1).
 */
import { readFileSync } from 'node:fs';
import { join } from 'node:path';
import { buildForm, readValues } from '../../src/controllers/prunt/config-ir';
import { configSchemaSchema, configValuesSchema } from '../../src/controllers/prunt/wire';
import { isValueNode } from '../../src/forms/ir';
import { FormModel, valueOf } from '../../src/forms/model';
import { heapMiB, measure, report } from './util';

const dir = join(process.cwd(), 'tests/fixtures/prunt');
const schemaText = readFileSync(join(dir, 'config-schema.json'), 'utf8');
const valuesText = readFileSync(join(dir, 'config-values.json'), 'utf8');

const heap0 = heapMiB();
const build = measure(30, () => {
  buildForm(configSchemaSchema.parse(JSON.parse(schemaText)), schemaText);
});
report({ name: 'Board 3: parse + validate (zod) + build form IR', ...build });

const pf = buildForm(configSchemaSchema.parse(JSON.parse(schemaText)), schemaText);
const values = configValuesSchema.parse(JSON.parse(valuesText)).Values;
const load = measure(30, () => {
  const m = new FormModel(pf.form);
  m.setBase(readValues(pf, values));
});
report({
  name: 'Board 3: read values + create model + load',
  ...load,
  fields: [...pf.form.nodes.values()].filter(isValueNode).length,
});

const model = new FormModel(pf.form);
model.setBase(readValues(pf, values));
const field = 'Steppers$STEPPER_1$Run current';
let i = 0;
const edit = measure(2000, () => {
  i++;
  model.set(field, String(1 + (i % 20) / 10));
});
report({ name: 'Board 3: one edit (valid, typed text)', ...edit });
const editInvalid = measure(2000, () => {
  i++;
  model.set(field, i % 2 ? '9' : '1.5');
});
report({ name: 'Board 3: one edit toggling an error (badge counts recomputed)', ...editInvalid });

// Every value field subscribes to its own slice, as FieldRow does: count who would re-render.
let renders = 0;
for (const [id, n] of pf.form.nodes) {
  if (!isValueNode(n)) continue;
  let prev = valueOf(model.store.getState(), pf.form, id);
  model.store.subscribe((s) => {
    const next = valueOf(s, pf.form, id);
    if (next !== prev) {
      renders++;
      prev = next;
    }
  });
}
const before = renders;
model.set(field, '2.25');
report({ name: 'Board 3: field components re-rendered by one edit', renders: renders - before });
const withSubs = measure(500, () => {
  i++;
  model.set(field, String(1 + (i % 20) / 10));
});
report({ name: 'Board 3: one edit with 682 field subscribers', ...withSubs });
report({ name: 'Board 3 form heap', heap_mib: heapMiB(), heap_before_mib: heap0 });
