import { readFileSync } from 'node:fs';
import { join } from 'node:path';
import { afterEach, beforeEach, describe, expect, it, vi } from 'vitest';
import { PruntSimulator } from './sim';

const dir = join(process.cwd(), 'tests/fixtures/prunt');
const json = (f: string): unknown => JSON.parse(readFileSync(join(dir, f), 'utf8'));

let sim: PruntSimulator | null = null;
beforeEach(() => vi.useFakeTimers());
afterEach(() => {
  sim?.dispose();
  sim = null;
  vi.useRealTimers();
});

const post = (s: PruntSimulator, path: string, body: string) =>
  s.fetch(new Request(`http://x${path}`, { method: 'POST', body }), path);
const get = (s: PruntSimulator, path: string) => s.fetch(new Request(`http://x${path}`), path);

describe('PruntSimulator (flat API) reproduces the fixtures', () => {
  it('serves the exact schema, values and status schema', async () => {
    sim = new PruntSimulator({ id: 'p', name: 'p', api: 'flat' });
    await sim.ready;
    expect(await (await get(sim, '/config/schema')).json()).toEqual(json('config-schema.json'));
    expect(await (await get(sim, '/config/values')).json()).toEqual(json('config-values.json'));
    expect(await (await get(sim, '/status/schema')).json()).toEqual(json('status-schema.json'));
    expect(await (await get(sim, '/update_check')).json()).toEqual(json('update-check.json'));
    expect((await get(sim, '/update-check')).status).toBe(404);
    expect(await (await get(sim, '/uploads/')).json()).toEqual(json('uploads-list.json'));
  });

  it('answers the schema-error POST exactly: 200, nothing saved, verbatim messages', async () => {
    sim = new PruntSimulator({ id: 'p', name: 'p', api: 'flat' });
    await sim.ready;
    const body =
      '{"Kinematics$Maximum acceleration":-5,"Steppers$STEPPER_4$Distance per step$Gear with circumference$Gear ratio$Numerator":50,"Steppers$STEPPER_4$Distance per step$Gear with circumference$Gear ratio$Denominator":0,"Steppers$STEPPER_1$TPFD":4.5,"Kinematics$Maximum jerkk":1}';
    const r = await post(sim, '/config/values', body);
    expect(r.status).toBe(200);
    expect(await r.json()).toEqual(json('config-post-schema-error.json'));
  });

  it('answers the semantic-error POST exactly: the value is saved and the error reported', async () => {
    sim = new PruntSimulator({ id: 'p', name: 'p', api: 'flat' });
    await sim.ready;
    const r = await post(sim, '/config/values', '{"Fans$FAN_2$PWM frequency":25000}');
    expect(await r.json()).toEqual(json('config-post-semantic-error.json'));
    expect(sim.values['Fans$FAN_2$PWM frequency']).toBe(25000);
  });

  it('GET /config/values reads (counted) and changes nothing', async () => {
    sim = new PruntSimulator({ id: 'p', name: 'p', api: 'flat' });
    await sim.ready;
    const before = JSON.stringify(sim.values);
    await get(sim, '/config/values');
    await get(sim, '/config/values');
    expect(sim.configReads).toBe(2);
    expect(JSON.stringify(sim.values)).toBe(before);
  });

  it('sends ticks every Nth 50 ms tick according to the divisor', async () => {
    sim = new PruntSimulator({ id: 'p', name: 'p', api: 'flat' });
    await sim.ready;
    const got: string[] = [];
    const h = sim.socket('/websocket/everything', { send: (d) => got.push(d), close: () => undefined });
    expect(JSON.parse(got[0] as string)).toEqual({ Server_Start_Time: ' 86012.004567890' });
    vi.advanceTimersByTime(1000);
    expect(got.filter((g) => g.startsWith('{"Status"')).length).toBe(20);
    h?.message('10');
    got.length = 0;
    vi.advanceTimersByTime(1000);
    expect(got.length).toBe(2);
    h?.message('not a number');
    h?.message('0');
    got.length = 0;
    vi.advanceTimersByTime(1000);
    expect(got.length).toBe(2);
  });

  it('runs a file: positions and temperatures move; a second file is refused with the real text', async () => {
    sim = new PruntSimulator({ id: 'p', name: 'p', api: 'flat' });
    await sim.ready;
    expect((await post(sim, '/run-file', 'benchy.gcode')).status).toBe(204);
    const r = await post(sim, '/run-file', 'calibration_cube.gcode');
    expect(r.status).toBe(500);
    expect(await r.text()).toBe('Can not run file while another file is running.');
    const t0 = sim.temps['THERMISTOR_1'] ?? 0;
    vi.advanceTimersByTime(5000);
    expect(sim.temps['THERMISTOR_1']).toBeGreaterThan(t0 + 5);
    expect(sim.positions['E_AXIS']).toBeGreaterThan(0);
    const st = (await (await get(sim, '/status/values')).json()) as { Status: Record<string, unknown> };
    expect(st.Status['Current_File_Name']).toBe('uploads/benchy.gcode');
  });
});

describe('PruntSimulator (module API)', () => {
  it('rejects a patch without versions, all or nothing', async () => {
    sim = new PruntSimulator({ id: 'p', name: 'p', api: 'module' });
    await sim.ready;
    const r = await post(
      sim,
      '/config/values',
      JSON.stringify({ Config: { Fans: { Config: { Fans: { FAN_2: { 'PWM frequency': 50 } } } } } }),
    );
    const body = (await r.json()) as { Errors: Array<{ Path: string[] }> };
    expect(body.Errors.map((e) => e.Path)).toEqual([['Prunt config version'], ['Config', 'Fans', 'Version']]);
    expect(sim.values['Fans$FAN_2$PWM frequency']).toBe(30);
  });

  it('applies a versioned patch and reports semantic errors by Path', async () => {
    sim = new PruntSimulator({ id: 'p', name: 'p', api: 'module' });
    await sim.ready;
    const patch = {
      'Prunt config version': 1,
      Config: { Fans: { Version: 1, Config: { Fans: { FAN_2: { 'PWM frequency': 200 } } } } },
    };
    const body = (await (await post(sim, '/config/values', JSON.stringify(patch))).json()) as {
      Errors: Array<{ Path: string[]; Message: string }>;
    };
    expect(sim.values['Fans$FAN_2$PWM frequency']).toBe(200);
    expect(body.Errors[0]?.Path).toEqual(['Config', 'Fans', 'Config', 'Fans', 'FAN_2', 'PWM frequency']);
  });

  it('ticks carry the exact v2026 spacing and a new start time after reload', async () => {
    sim = new PruntSimulator({ id: 'p', name: 'p', api: 'module' });
    await sim.ready;
    const got: string[] = [];
    let closed = 0;
    sim.socket('/websocket/everything', { send: (d) => got.push(d), close: () => void closed++ });
    vi.advanceTimersByTime(50);
    expect(got[1]).toMatch(
      /^\{"Status_Values":\{.*\}, "Smart_Plug":\{.*\}, "Server_Exception":null, "Startup": "Done"\}$/,
    );
    await post(sim, '/reload-server', '');
    vi.advanceTimersByTime(100);
    expect(closed).toBe(1);
    const again: string[] = [];
    sim.socket('/websocket/everything', { send: (d) => again.push(d), close: () => undefined });
    expect(again[0]).not.toBe(got[0]);
    vi.advanceTimersByTime(50);
    expect(again[1]).toContain('"Startup": "Waiting"');
  });
});

describe('PruntSimulator demo control', () => {
  it('runs a job for several minutes through its own state, then starts it again', async () => {
    sim = new PruntSimulator({ id: 'p', name: 'p', api: 'module' });
    const demo = sim.controls().find((c) => c.id === 'demo');
    expect(demo?.label).toBe('Start a demo job');
    demo?.run(); // before the board data loaded: the tick loop starts it
    await sim.ready;
    vi.advanceTimersByTime(100);
    const status = () => sim?.moduleStatus()['Internal Status Reporter']?.['Print status'];
    expect(status()?.['File name']).toBe('uploads/benchy.gcode');
    vi.advanceTimersByTime(60_000);
    const line = Number(status()?.['Current line']);
    expect(line).toBeGreaterThan(10);
    expect(sim.temps['THERMISTOR_1']).toBeGreaterThan(100);
    // Still running after two minutes: it lasts several minutes, not seconds.
    vi.advanceTimersByTime(60_000);
    expect(status()?.['File name']).toBe('uploads/benchy.gcode');
    expect(Number(status()?.['Current line'])).toBeGreaterThan(line);
    // Done after about four minutes, idle for a while, then again.
    vi.advanceTimersByTime(125_000);
    expect(status()?.['File name']).toBe('');
    vi.advanceTimersByTime(20_000);
    expect(status()?.['File name']).toBe('uploads/benchy.gcode');
    expect(Number(status()?.['Current line'])).toBeLessThan(line);
    // The real server still refuses a second file while the demo runs.
    expect((await post(sim, '/run-file', 'calibration_cube.gcode')).status).toBe(500);
    // Pause holds the line; an operator's cancel ends the loop.
    sim.paused = true;
    const held = status()?.['Current line'];
    vi.advanceTimersByTime(5_000);
    expect(status()?.['Current line']).toBe(held);
    sim.paused = false;
    expect((await post(sim, '/cancel', '')).status).toBe(204);
    expect(sim.demoRunning).toBe(false);
    vi.advanceTimersByTime(60_000);
    expect(status()?.['File name']).toBe('');
  });
});
