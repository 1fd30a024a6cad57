import { readFileSync } from 'node:fs';
import { join } from 'node:path';
import { describe, expect, it } from 'vitest';
import { FormModel } from '../../forms/model';
import {
  buildFlatPatch,
  buildForm,
  buildModulePatch,
  flatIdForKey,
  moduleIdForPath,
  placeErrors,
  readValues,
} from './config-ir';
import { loadBoard3, moduleSchema, modulePathOf, toModuleValues } from './sim/board';
import { configSchemaSchema, configValuesSchema } from './wire';

await loadBoard3();

const dir = join(process.cwd(), 'tests/fixtures/prunt');
const json = (f: string): unknown => JSON.parse(readFileSync(join(dir, f), 'utf8'));

const flatForm = () => buildForm(configSchemaSchema.parse(json('config-schema.json')));
const moduleForm = () => buildForm(configSchemaSchema.parse(moduleSchema()));

describe('form model from the flat Board 3 schema', () => {
  const pf = flatForm();
  it('has one value node per value key (682 values; ratios count twice)', () => {
    let values = 0;
    for (const n of pf.form.nodes.values()) {
      if (n.kind === 'ratio') values += 2;
      else if (n.kind !== 'group' && n.kind !== 'unknown') values += 1;
    }
    expect(values).toBe(682);
    expect(pf.form.roots[0]).toBe('Prunt');
  });

  it('maps kinds: tabbed sequences, variants, ratios, numbers with units', () => {
    const steppers = pf.form.nodes.get('Steppers');
    expect(steppers?.kind === 'group' && steppers.tabbed).toBe(true);
    const dps = pf.form.nodes.get('Steppers$STEPPER_1$Distance per step');
    expect(dps?.kind).toBe('variant');
    const ratio = pf.form.nodes.get('Steppers$STEPPER_1$Distance per step$Lead screw$Gear ratio');
    expect(ratio).toMatchObject({ kind: 'ratio', min: 1e-100, max: 1e100 });
    expect(pf.form.nodes.get('Steppers$STEPPER_1$Run current')).toMatchObject({
      kind: 'float',
      unit: 'amp',
      max: 3,
    });
    expect(pf.form.nodes.get('Steppers$STEPPER_1$TPFD')).toMatchObject({ kind: 'integer', min: 0, max: 15 });
  });

  it('reads every value of the example printer, and of the defaults', () => {
    for (const f of ['config-values.json', 'config-values-defaults.json']) {
      const v = configValuesSchema.parse(json(f));
      const base = readValues(pf, v.Values);
      const nodes = [...pf.form.nodes.values()].filter((n) => n.kind !== 'group');
      expect(Object.keys(base).length).toBe(nodes.length);
    }
    const base = readValues(pf, configValuesSchema.parse(json('config-values.json')).Values);
    expect(base['Steppers$STEPPER_4$Distance per step$Gear with circumference$Gear ratio']).toEqual({
      numerator: 50,
      denominator: 17,
    });
    expect(base['Steppers$STEPPER_1$Distance per step']).toBe('Gear with tooth count and pitch');
  });

  it('places every error of both POST fixtures under its field or group', () => {
    const bad = configValuesSchema.parse(json('config-post-schema-error.json'));
    const placed = placeErrors(pf, bad.Errors);
    expect(placed.map((p) => p.id)).toEqual([
      'Kinematics$Maximum acceleration',
      'Steppers$STEPPER_4$Distance per step$Gear with circumference$Gear ratio',
      'Steppers$STEPPER_1$TPFD',
      'Kinematics', // "Maximum jerkk" is not a field: the error goes to its group
    ]);
    expect(placed.every((p) => p.schemaError)).toBe(true);
    const sem = placeErrors(pf, configValuesSchema.parse(json('config-post-semantic-error.json')).Errors);
    expect(sem).toEqual([expect.objectContaining({ id: 'Fans$FAN_2$PWM frequency', schemaError: false })]);
  });

  it('builds a flat patch with only the changed keys; a variant switch sends its subtree', () => {
    const base = readValues(pf, configValuesSchema.parse(json('config-values.json')).Values);
    const model = new FormModel(pf.form);
    model.setBase(base);
    model.set('Steppers$STEPPER_1$Run current', '1.5');
    model.set('Steppers$STEPPER_4$Distance per step$Gear with circumference$Gear ratio', {
      numerator: 40,
      denominator: '20',
    });
    let patch = buildFlatPatch(pf, model.changes(), (id) => model.value(id));
    expect(patch).toEqual({
      'Steppers$STEPPER_1$Run current': 1.5,
      'Steppers$STEPPER_4$Distance per step$Gear with circumference$Gear ratio$Numerator': 40,
      'Steppers$STEPPER_4$Distance per step$Gear with circumference$Gear ratio$Denominator': 20,
    });
    model.discardAll();
    model.set('Heaters$HEATER_2$Control method', 'PID');
    patch = buildFlatPatch(pf, model.changes(), (id) => model.value(id));
    expect(patch['Heaters$HEATER_2$Control method']).toBe('PID');
    expect(patch['Heaters$HEATER_2$Control method$Bang bang$Hysteresis']).toBe(2);
    expect(patch['Heaters$HEATER_2$Control method$PID$Proportional scale']).toBe(0);
    expect(Object.keys(patch).some((k) => k.startsWith('Heaters$HEATER_1'))).toBe(false);
  });
});

describe('form model from the module API', () => {
  const pf = moduleForm();
  const values = toModuleValues(
    configValuesSchema.parse(json('config-values.json')).Values as Record<string, string>,
  ) as Record<string, unknown>;

  it('has the modules as roots with versions and defaults', () => {
    expect(pf.api).toBe('module');
    expect(pf.form.roots).toContain('Fans');
    expect(pf.moduleVersions['Fans']).toBe(1);
    const steppers = pf.form.nodes.get('Steppers$Steppers');
    expect(steppers?.kind === 'group' && steppers.tabbed).toBe(true);
    expect(pf.form.nodes.get('Prunt$Prunt$Enabled')).toMatchObject({ kind: 'boolean', default: false });
    const r = pf.form.nodes.get('Steppers$Steppers$STEPPER_1$Distance per step$Lead screw$Gear ratio');
    expect(r?.kind === 'ratio' && r.default).toEqual({ numerator: 1, denominator: 1 });
  });

  it('resolves Present_When and keeps Experimental and String', () => {
    const host = pf.form.nodes.get('Smart Plug$Smart plug$Host');
    expect(host?.kind).toBe('string');
    expect(host?.presentWhen).toEqual({ field: 'Smart Plug$Smart plug$Enabled', values: [true] });
    expect(pf.form.nodes.get('Smart Plug$Smart plug$Watchdog seconds')?.experimental).toBe(true);
    const model = new FormModel(pf.form);
    model.setBase(readValues(pf, values));
    expect(model.isActive('Smart Plug$Smart plug$Host')).toBe(false);
    model.set('Smart Plug$Smart plug$Enabled', true);
    expect(model.isActive('Smart Plug$Smart plug$Host')).toBe(true);
    expect(model.isActive('Smart Plug$Smart plug$Watchdog seconds')).toBe(false);
    model.setShowExperimental(true);
    expect(model.isActive('Smart Plug$Smart plug$Watchdog seconds')).toBe(true);
  });

  it('reads nested values the same as the flat ones', () => {
    const flat = readValues(flatForm(), configValuesSchema.parse(json('config-values.json')).Values);
    const mod = readValues(pf, values);
    for (const [id, v] of Object.entries(flat)) {
      const section = id.split('$')[0] as string;
      expect(mod[`${section}$${id}`]).toEqual(v);
    }
  });

  it('maps error paths (through Children, Selected, Numerator) to nodes', () => {
    expect(moduleIdForPath(pf, modulePathOf('Fans$FAN_2$PWM frequency'))).toBe(
      'Fans$Fans$FAN_2$PWM frequency',
    );
    expect(moduleIdForPath(pf, modulePathOf('Heaters$HEATER_1$Control method'))).toBe(
      'Heaters$Heaters$HEATER_1$Control method',
    );
    expect(moduleIdForPath(pf, modulePathOf('Heaters$HEATER_1$Control method$PID$Integral scale'))).toBe(
      'Heaters$Heaters$HEATER_1$Control method$PID$Integral scale',
    );
    expect(
      moduleIdForPath(
        pf,
        modulePathOf('Steppers$STEPPER_4$Distance per step$Lead screw$Gear ratio$Denominator'),
      ),
    ).toBe('Steppers$Steppers$STEPPER_4$Distance per step$Lead screw$Gear ratio');
    // A path that ends inside an unknown name points at the deepest group it reached.
    expect(moduleIdForPath(pf, ['Config', 'Kinematics', 'Config', 'Kinematics', 'Maximum jerkk'])).toBe(
      'Kinematics$Kinematics',
    );
    expect(moduleIdForPath(pf, ['Config', 'Nope'])).toBeNull();
  });

  it('builds a module patch with versions; a change inside a variant sends the whole variant', () => {
    const model = new FormModel(pf.form);
    model.setBase(readValues(pf, values));
    model.set('Steppers$Steppers$STEPPER_2$Run current', 1.1);
    model.set('Heaters$Heaters$HEATER_1$Control method$PID$Integral scale', '0.003');
    const patch = buildModulePatch(pf, model.changes(), (id) => model.value(id));
    expect(patch['Prunt config version']).toBe(1);
    expect(Object.keys(patch.Config).sort()).toEqual(['Heaters', 'Steppers']);
    expect(patch.Config['Steppers']).toEqual({
      Version: 1,
      Config: { Steppers: { STEPPER_2: { 'Run current': 1.1 } } },
    });
    const cm = (patch.Config['Heaters']?.Config['Heaters'] as Record<string, Record<string, unknown>>)[
      'HEATER_1'
    ]?.['Control method'] as {
      Selected: string;
      Children: Record<string, Record<string, number>>;
    };
    expect(cm.Selected).toBe('PID');
    expect(cm.Children['PID']?.['Integral scale']).toBe(0.003);
    expect(cm.Children['Bang bang']).toEqual({ Hysteresis: 0 }); // non-selected children are present
  });

  it('the flat key lookup falls back to the nearest group', () => {
    const f = flatForm();
    expect(flatIdForKey(f, 'Steppers$STEPPER_1$Nope')).toBe('Steppers$STEPPER_1');
    expect(flatIdForKey(f, 'Nothing')).toBeNull();
  });
});

describe('form model from the other fixtures', () => {
  it('builds the simulator-variant schema (Basic steppers, fixed-switching fans)', () => {
    const pf = buildForm(configSchemaSchema.parse(json('config-schema.simulator.json')));
    expect(pf.form.nodes.get('Steppers$X_AXIS$Microsteps')).toMatchObject({ kind: 'float', min: 1 });
    const fan = pf.form.nodes.get('Fans$FAN_1');
    expect(fan?.kind === 'group' && fan.children).toEqual([
      'Fans$FAN_1$Invert PWM output',
      'Fans$FAN_1$PWM frequency',
      'Fans$FAN_1$Control method',
    ]);
    const steppers = pf.form.nodes.get('Steppers');
    expect(steppers?.kind === 'group' && steppers.tabbed).toBe(true);
  });

  it('reads the v2026 fans fragment (nested variant values) through a schema of the same shape', () => {
    // The fragment has no schema of its own: this one follows prunt-config.ads for the Fans module.
    const leaf = (Kind: string, extra: object = {}) => ({ Kind, Description: '', ...extra });
    const method = {
      Kind: 'Sequence',
      Description: '',
      Tabbed: false,
      Children: {
        Kind: {
          Kind: 'Variant',
          Description: '',
          Default: 'Always_On',
          Children: {
            Always_On: {
              Kind: 'Sequence',
              Description: '',
              Tabbed: false,
              Children: {
                Always_On: {
                  Kind: 'Sequence',
                  Description: '',
                  Tabbed: false,
                  Children: { Duty_Cycle: leaf('Float', { Min: 0, Max: 1, Unit: '', Default: 1 }) },
                },
              },
            },
            Dynamic_Duty_Cycle: {
              Kind: 'Sequence',
              Description: '',
              Tabbed: false,
              Children: {
                Dynamic_Duty_Cycle: {
                  Kind: 'Sequence',
                  Description: '',
                  Tabbed: false,
                  Children: {
                    Disable_Below: leaf('Float', { Min: 0, Max: 1, Unit: '', Default: 0 }),
                    Maximum_Duty_Cycle: leaf('Float', { Min: 0, Max: 1, Unit: '', Default: 1 }),
                  },
                },
              },
            },
          },
        },
      },
    };
    const fan = {
      Kind: 'Sequence',
      Description: '',
      Tabbed: false,
      Children: { Invert_PWM_Output: leaf('Boolean', { Default: false }), Control_Method: method },
    };
    const schema = {
      'Prunt config version': 1,
      Config: {
        Fans: {
          Version: 1,
          Config: {
            Fans: {
              Kind: 'Sequence',
              Description: '',
              Tabbed: true,
              Children: { DUMMY_FAN: fan, LOW_SIDE_DUMMY_FAN: fan, HIGH_SIDE_DUMMY_FAN: fan },
            },
          },
        },
      },
    };
    const pf = buildForm(configSchemaSchema.parse(schema));
    const values = configValuesSchema.parse(json('v2026/config-values.fans-fragment.json')).Values;
    const base = readValues(pf, values);
    expect(base['Fans$Fans$DUMMY_FAN$Control_Method$Kind']).toBe('Dynamic_Duty_Cycle');
    expect(
      base['Fans$Fans$DUMMY_FAN$Control_Method$Kind$Dynamic_Duty_Cycle$Dynamic_Duty_Cycle$Disable_Below'],
    ).toBe(0.25);
    expect(
      base[
        'Fans$Fans$LOW_SIDE_DUMMY_FAN$Control_Method$Kind$Dynamic_Duty_Cycle$Dynamic_Duty_Cycle$Maximum_Duty_Cycle'
      ],
    ).toBe(0.5);
    expect(base['Fans$Fans$HIGH_SIDE_DUMMY_FAN$Invert_PWM_Output']).toBe(true);
    // Values the fragment leaves out fall back to the schema default.
    const model = new FormModel(pf.form);
    model.setBase(base);
    expect(model.value('Fans$Fans$DUMMY_FAN$Invert_PWM_Output')).toBe(false);
    // An edit inside the variant sends the variant whole, with the module version.
    model.set(
      'Fans$Fans$DUMMY_FAN$Control_Method$Kind$Dynamic_Duty_Cycle$Dynamic_Duty_Cycle$Disable_Below',
      '0.3',
    );
    const patch = buildModulePatch(pf, model.changes(), (id) => model.value(id));
    expect(patch).toEqual({
      'Prunt config version': 1,
      Config: {
        Fans: {
          Version: 1,
          Config: {
            Fans: {
              DUMMY_FAN: {
                Control_Method: {
                  Kind: {
                    Selected: 'Dynamic_Duty_Cycle',
                    Children: {
                      Always_On: { Always_On: { Duty_Cycle: 1 } },
                      Dynamic_Duty_Cycle: {
                        Dynamic_Duty_Cycle: { Disable_Below: 0.3, Maximum_Duty_Cycle: 0.8 },
                      },
                    },
                  },
                },
              },
            },
          },
        },
      },
    });
  });
});
