import { readFileSync } from 'node:fs';
import { join } from 'node:path';
import { describe, expect, it } from 'vitest';
import {
  configSchemaSchema,
  configValuesSchema,
  statusSchemaSchema,
  statusValuesSchema,
  updateCheckSchema,
  uploadsSchema,
  wsMessageSchema,
  type WsMessage,
} from './wire';

const dir = join(process.cwd(), 'tests/fixtures/prunt');
const text = (f: string) => readFileSync(join(dir, f), 'utf8');
const json = (f: string): unknown => JSON.parse(text(f));

describe('Prunt wire schemas against every fixture', () => {
  it('detects the flat API from the Board 3 schema and keeps every section', () => {
    const r = configSchemaSchema.parse(json('config-schema.json'));
    expect(r.api).toBe('flat');
    if (r.api !== 'flat') return;
    expect(Object.keys(r.schema)).toEqual([
      'Prunt',
      'Steppers',
      'Kinematics',
      'Input switches',
      'Thermistors',
      'Heaters',
      'Lasers',
      'Homing',
      'Fans',
      'Input shaping',
      'G-code assignments',
    ]);
    const run = r.schema['Steppers']?.Children?.['STEPPER_1']?.Children?.['Run current'];
    expect(run).toMatchObject({ Kind: 'Float', Min: 0.125, Max: 3, Unit: 'amp' });
  });

  it('parses the simulator-variant schema (Basic steppers)', () => {
    const r = configSchemaSchema.parse(json('config-schema.simulator.json'));
    expect(r.api).toBe('flat');
  });

  it('parses values, defaults and both POST replies', () => {
    for (const f of [
      'config-values.json',
      'config-values-defaults.json',
      'config-post-schema-error.json',
      'config-post-semantic-error.json',
    ]) {
      const r = configValuesSchema.parse(json(f));
      expect(Object.keys(r.Values).length).toBe(682);
    }
    const bad = configValuesSchema.parse(json('config-post-schema-error.json'));
    expect(bad.Errors.map((e) => e.Key)).toContain('Kinematics$Maximum jerkk');
    const defaults = configValuesSchema.parse(json('config-values-defaults.json'));
    expect(defaults.Errors).toEqual([
      { Key: 'Prunt$Enabled', Message: 'Prunt is disabled. Enable after setting other options.' },
    ]);
  });

  it('parses the v2026 fans fragment with Path-less errors', () => {
    const r = configValuesSchema.parse(json('v2026/config-values.fans-fragment.json'));
    expect(r.Values['Prunt config version']).toBe(1);
    expect(r.Errors).toEqual([]);
  });

  it('parses both status schema generations', () => {
    const flat = statusSchemaSchema.parse(json('status-schema.json'));
    expect(flat.api).toBe('flat');
    if (flat.api === 'flat') expect(flat.schema['StallGuard_Values']).toContain('STEPPER_1 (SG4)');
    const mod = statusSchemaSchema.parse(json('v2026/status-schema.internal-status-reporter.json'));
    expect(mod.api).toBe('module');
    if (mod.api === 'module') {
      expect(mod.schema['Internal Status Reporter']?.['Print status']?.['File name']).toMatchObject({
        Kind: 'String',
        Condition: '',
      });
    }
  });

  it('parses both status value generations (Ada images are numbers)', () => {
    const flat = statusValuesSchema.parse(json('status-values.json'));
    expect(flat.api).toBe('flat');
    if (flat.api === 'flat') {
      expect(flat.values['Position']).toMatchObject({ X_AXIS: 117.5 });
      expect(flat.values['Current_File_Line']).toBe(18342);
    }
    const mod = statusValuesSchema.parse(json('v2026/status-values.internal-status-reporter.json'));
    expect(mod.api).toBe('module');
  });

  it('reads every WebSocket message of both generations', () => {
    const parse = (f: string): WsMessage[] =>
      text(f)
        .split('\n')
        .filter((l) => l.trim())
        .map((l) => wsMessageSchema.parse(JSON.parse(l)));
    const flat = parse('websocket-messages.jsonl');
    expect(flat.map((m) => m.type)).toEqual(['start', 'log', 'log', 'tick', 'tick', 'log']);
    expect(flat[0]).toEqual({ type: 'start', startTime: '86012.004567890' });
    const tick = flat[3];
    expect(tick?.type === 'tick' && tick.api).toBe('flat');
    expect(tick?.type === 'tick' && tick.startup).toBe('Done');

    const mod = parse('v2026/websocket-messages.jsonl');
    expect(mod.map((m) => m.type)).toEqual([
      'start',
      'tick',
      'tick',
      'gcode',
      'log',
      'gcode',
      'gcode',
      'tick',
    ]);
    const waiting = mod[1];
    expect(waiting?.type === 'tick' && waiting.startup).toBe('Waiting');
    const failed = mod[6];
    expect(failed).toEqual({
      type: 'gcode',
      id: '8',
      kind: 'Failed',
      message: 'Position auto-report interval must be 0.1 or higher.',
    });
    const exc = mod[7];
    expect(exc?.type === 'tick' && exc.api === 'module' && exc.exception).toEqual({
      message: 'raised CONSTRAINT_ERROR : example recoverable error\n',
      fatal: false,
    });
  });

  it('maps unknown enum values to "unknown (raw …)" instead of failing', () => {
    const m = wsMessageSchema.parse({ Status_Values: {}, Startup: 'Exploding' });
    expect(m.type === 'tick' && m.startup).toBe('unknown (raw Exploding)');
    const g = wsMessageSchema.parse({ Gcode_Command: { ID: 3, Kind: 'Queued' } });
    expect(g).toEqual({ type: 'gcode', id: '3', kind: 'unknown (raw Queued)', message: null });
  });

  it('coerces numbers sent as strings and keeps unknown node kinds', () => {
    const r = configSchemaSchema.parse({
      A: { Kind: 'Integer', Description: 'x', Min: '1', Max: '5', Unit: '' },
      B: { Kind: 'Colour', Description: '' },
    });
    expect(r.api === 'flat' && r.schema['A']?.Min).toBe(1);
    expect(r.api === 'flat' && r.schema['B']?.Kind).toBe('Colour');
  });

  it('rejects a malformed payload with the failing path', () => {
    const r = configSchemaSchema.safeParse({
      'Prunt config version': 1,
      Config: { Fans: { Version: 1, Config: { X: { Description: 'no kind' } } } },
    });
    expect(r.success).toBe(false);
    expect(r.error?.issues[0]?.path.join('.')).toContain('Fans');
  });

  it('parses uploads and the update check', () => {
    expect(uploadsSchema.parse(json('uploads-list.json'))).toEqual([
      'benchy.gcode',
      'calibration_cube.gcode',
      'first_layer_test.gcode',
    ]);
    expect(updateCheckSchema.parse(json('update-check.json'))).toEqual({ Available: false, URL: '' });
  });
});
