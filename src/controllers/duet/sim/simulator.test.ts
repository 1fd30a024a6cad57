import { afterEach, beforeEach, describe, expect, it, vi } from 'vitest';
import { fixtureJson } from '../fixtures.test-util';
import { applyPatch, takeFullModel, type JsonObject } from '../patch';
import { objectModelSchema } from '../wire';
import { baseModel } from './data/model';
import { DuetSimulator } from './simulator';

let now = 1_700_000_000_000;
let sim: DuetSimulator;

beforeEach(() => {
  vi.useFakeTimers();
  now = 1_700_000_000_000;
  vi.setSystemTime(now);
  sim = new DuetSimulator({ id: 'd', name: 'duet-sim', now: () => Date.now(), tickMs: 250 });
});
afterEach(() => {
  sim.dispose();
  vi.useRealTimers();
});

const req = (method: string, path: string, init: { body?: string; key?: string | null } = {}) =>
  sim.fetch(
    new Request(`http://x/machines/d${path}`, {
      method,
      body: init.body,
      headers: init.key ? { 'X-Session-Key': init.key } : {},
    }),
    path,
  );

async function connect(): Promise<string> {
  const r = await req('GET', '/machine/connect');
  expect(r.status).toBe(200);
  return ((await r.json()) as { sessionKey: string }).sessionKey;
}

function openSocket(key: string) {
  const frames: string[] = [];
  const closes: number[] = [];
  const h = sim.socket(`/machine?sessionKey=${key}`, {
    send: (d) => frames.push(d),
    close: (c) => closes.push(c ?? 0),
  })!;
  return { frames, closes, h };
}

describe('DuetSimulator', () => {
  it('has the shape of the real model (same top-level keys, validates)', () => {
    const real = fixtureJson('object-model/model_geminiv2.json');
    const mine = baseModel('x');
    expect(Object.keys(mine).sort()).toEqual(Object.keys(real).sort());
    for (const section of ['state', 'job']) {
      const want = Object.keys(real[section] as JsonObject).filter(
        (k) => !['atxPowerPort', 'deferredPowerDown'].includes(k),
      );
      for (const k of want) expect(Object.keys(mine[section] as JsonObject), `${section}.${k}`).toContain(k);
    }
    expect(objectModelSchema.safeParse(mine).success).toBe(true);
  });

  it('sends the full model first and nothing more until OK, then one coalesced patch', async () => {
    const key = await connect();
    const { frames, h } = openSocket(key);
    expect(frames).toHaveLength(1);
    let model = takeFullModel(JSON.parse(frames[0]!) as JsonObject).model;
    expect((model['state'] as JsonObject)['status']).toBe('idle');
    sim.runCode('M140 S60');
    vi.advanceTimersByTime(3000);
    expect(frames).toHaveLength(1); // no OK yet: nothing sent
    h.message('OK\n');
    expect(frames).toHaveLength(2);
    const patch = JSON.parse(frames[1]!) as JsonObject;
    model = applyPatch(model, patch).model;
    const bed = ((model['heat'] as JsonObject)['heaters'] as JsonObject[])[0]!;
    expect(bed['active']).toBe(60);
    expect(bed['current'] as number).toBeGreaterThan(21);
    // sparse: the hotend item is {} (unchanged) or only its changed keys, and the hole stays null
    const heaters = (patch['heat'] as JsonObject)['heaters'] as unknown[];
    expect(heaters).toHaveLength(4);
    expect(heaters[2]).toBeNull();
    vi.advanceTimersByTime(1000);
    expect(frames).toHaveLength(2);
    h.message('PING\n');
    expect(frames[2]).toBe('PONG\n');
  });

  it('expires a session 8 s after the last request when no socket is open', async () => {
    const key = await connect();
    vi.advanceTimersByTime(5000);
    expect((await req('GET', '/machine/noop', { key })).status).toBe(204);
    vi.advanceTimersByTime(7000);
    expect((await req('GET', '/machine/noop', { key })).status).toBe(204);
    vi.advanceTimersByTime(8500);
    expect((await req('GET', '/machine/noop', { key })).status).toBe(403);
    // an open socket keeps it alive
    const key2 = await connect();
    openSocket(key2);
    vi.advanceTimersByTime(60_000);
    expect((await req('GET', '/machine/status', { key: key2 })).status).toBe(200);
  });

  it('checks the password on connect', async () => {
    sim.password = 'secret';
    expect((await req('GET', '/machine/connect?password=wrong')).status).toBe(403);
    expect((await req('GET', '/machine/connect?password=secret')).status).toBe(200);
    expect((await req('GET', '/machine/status')).status).toBe(403);
  });

  it('runs a print: M32, heating, progress, M25, M0 with the messages', async () => {
    const key = await connect();
    const { frames, h } = openSocket(key);
    expect(sim.runCode('M32 "0:/gcodes/bracket.gcode"')).toBe('');
    expect(sim.status).toBe('processing');
    vi.advanceTimersByTime(120_000);
    const job = sim.model['job'] as JsonObject;
    expect(job['filePosition'] as number).toBeGreaterThan(0);
    expect(job['layer'] as number).toBeGreaterThan(0);
    expect(sim.runCode('M0')).toMatch(/^Warning/);
    sim.runCode('M25');
    vi.advanceTimersByTime(1000);
    expect(sim.status).toBe('paused');
    sim.runCode('M0');
    vi.advanceTimersByTime(1000);
    expect(sim.status).toBe('idle');
    expect(job['lastFileCancelled']).toBe(true);
    expect(sim.runCode('M25')).toMatch(/Cannot pause/);
    expect(sim.runCode('M4321')).toMatch(/^Error: M4321/);
    expect(sim.runCode('M32 "0:/gcodes/nope.gcode"')).toMatch(/Could not find/);
    // the messages went out as events
    h.message('OK');
    const all = frames.filter((f) => f.includes('"messages"')).join('');
    expect(all).toMatch(/Cancelled printing file 0:\/gcodes\/bracket.gcode/);
  });

  it('demo control: prints a file from the card over minutes and starts it again, without commands', () => {
    const demo = sim.controls().find((c) => c.id === 'demo');
    expect(demo?.label).toBe('Start a demo job');
    const job = sim.model['job'] as JsonObject;
    const heat = (sim.model['heat'] as JsonObject)['heaters'] as JsonObject[];
    demo!.run();
    expect(sim.codes).toEqual([]); // through the simulator's own state, not G-code
    expect(sim.status).toBe('processing');
    const file = job['file'] as JsonObject;
    expect(file['fileName']).toBe('0:/gcodes/bracket.gcode');
    expect(sim.fs.get(String(file['fileName']))).toBeDefined();
    // Warm-up first: heaters rise, nothing printed yet.
    vi.advanceTimersByTime(5_000);
    expect(heat[1]!['current'] as number).toBeGreaterThan(30);
    expect(job['filePosition']).toBe(0);
    // Then layers advance.
    vi.advanceTimersByTime(90_000);
    const layer1 = job['layer'] as number;
    const pos1 = job['filePosition'] as number;
    expect(layer1).toBeGreaterThan(0);
    vi.advanceTimersByTime(60_000);
    expect(job['layer'] as number).toBeGreaterThan(layer1);
    expect(job['filePosition'] as number).toBeGreaterThan(pos1);
    expect(sim.status).toBe('processing');
    const fans = sim.model['fans'] as JsonObject[];
    expect(fans[0]!['actualValue']).toBe(1); // part cooling on while printing
    // It finishes (a 4-minute print plus warm-up) ...
    vi.advanceTimersByTime(200_000);
    expect(job['lastFileName']).toBe('0:/gcodes/bracket.gcode');
    expect(job['lastFileCancelled']).toBe(false);
    // ... and starts again after a pause.
    vi.advanceTimersByTime(30_000);
    expect(sim.status).toBe('processing');
    expect((job['file'] as JsonObject)['fileName']).toBe('0:/gcodes/bracket.gcode');
    expect(sim.demoRunning).toBe(true);
  });

  it('demo control: a cancel by the operator ends the demo; it waits while the machine is busy', () => {
    sim.runCode('M37 P"0:/gcodes/gear.gcode"');
    const demo = sim.controls().find((c) => c.id === 'demo')!;
    demo.run();
    expect(sim.status).toBe('simulating'); // the running job is left alone
    vi.advanceTimersByTime(60_000);
    vi.advanceTimersByTime(25_000);
    expect(sim.status).toBe('processing'); // then the demo starts
    sim.runCode('M25');
    vi.advanceTimersByTime(1000);
    sim.runCode('M0');
    vi.advanceTimersByTime(1000);
    expect(sim.status).toBe('idle');
    vi.advanceTimersByTime(120_000);
    expect(sim.status).toBe('idle');
    expect(sim.demoRunning).toBe(false);
  });

  it('M112 halts, M999 resets', () => {
    sim.runCode('M32 "0:/gcodes/bracket.gcode"');
    sim.runCode('M112');
    expect(sim.status).toBe('halted');
    expect(sim.runCode('G28')).toMatch(/halted/);
    sim.runCode('M999');
    expect(sim.status).toBe('starting');
    vi.advanceTimersByTime(2000);
    expect(sim.status).toBe('idle');
    expect((sim.model['job'] as JsonObject)['lastFileAborted']).toBe(true);
  });

  it('message boxes of every mode and M292 answers', () => {
    for (let mode = 0; mode <= 7; mode++) {
      const seq = sim.raiseMessageBox(mode);
      const box = (sim.model['state'] as JsonObject)['messageBox'] as JsonObject;
      expect(box['mode']).toBe(mode);
      sim.runCode(`M292 P0 S${seq - 1}`); // stale: ignored
      expect((sim.model['state'] as JsonObject)['messageBox']).not.toBeNull();
      sim.runCode(
        mode === 7
          ? `M292 P0 S${seq} R{"abc"}`
          : mode === 3
            ? `M292 P1 S${seq}`
            : `M292 P0 S${seq} R{${mode}}`,
      );
      expect((sim.model['state'] as JsonObject)['messageBox']).toBeNull();
    }
    expect(sim.answers.find((a) => a.seq === 8)?.value).toBe('abc');
    expect(sim.answers.find((a) => a.seq === 4)?.cancelled).toBe(true);
  });

  it('keeps only the newest 500 M292 answers (it runs as long as the gateway)', () => {
    let last = 0;
    for (let i = 0; i < 1200; i++) {
      last = sim.raiseMessageBox(1);
      sim.runCode(`M292 P0 S${last}`);
    }
    expect(sim.answers).toHaveLength(500);
    expect(sim.answers.at(-1)?.seq).toBe(last);
  });

  it('files: list, upload, info with thumbnails, move with 409, delete', async () => {
    const key = await connect();
    const list = (await (
      await req('GET', `/machine/directory/${encodeURIComponent('0:/gcodes')}`, { key })
    ).json()) as Array<{ name: string; type: string }>;
    expect(list.map((e) => `${e.type}:${e.name}`)).toEqual([
      'd:enclosure',
      'f:bracket.gcode',
      'f:gear.gcode',
    ]);
    const info = (await (
      await req(
        'GET',
        `/machine/fileinfo/${encodeURIComponent('0:/gcodes/gear.gcode')}?readThumbnailContent=true`,
        { key },
      )
    ).json()) as JsonObject;
    const thumbs = info['thumbnails'] as JsonObject[];
    expect(thumbs[0]?.['format']).toBe('jpeg');
    expect(String(thumbs[0]?.['data'])).toMatch(/^\/9j\//);
    expect(info['numLayers']).toBe(20);
    expect(info['printTime']).toBe(420);
    const lid = (await (
      await req('GET', `/machine/fileinfo/${encodeURIComponent('0:/gcodes/enclosure/lid.gcode')}`, { key })
    ).json()) as JsonObject;
    expect((lid['thumbnails'] as JsonObject[])[0]?.['format']).toBe('qoi');
    expect((lid['thumbnails'] as JsonObject[])[0]?.['data']).toBeNull();
    expect(
      (
        await req(
          'PUT',
          `/machine/file/${encodeURIComponent('0:/gcodes/new.gcode')}?timeModified=2024-01-02T03:04:05Z`,
          { key, body: 'G28\n' },
        )
      ).status,
    ).toBe(201);
    const moveForm = (force: boolean) =>
      new URLSearchParams({
        from: '0:/gcodes/new.gcode',
        to: '0:/gcodes/gear.gcode',
        ...(force ? { force: 'true' } : {}),
      }).toString();
    expect((await req('POST', '/machine/file/move', { key, body: moveForm(false) })).status).toBe(409);
    expect((await req('POST', '/machine/file/move', { key, body: moveForm(true) })).status).toBe(204);
    expect(
      await (await req('GET', `/machine/file/${encodeURIComponent('0:/gcodes/gear.gcode')}`, { key })).text(),
    ).toBe('G28\n');
    expect(
      (await req('DELETE', `/machine/file/${encodeURIComponent('0:/gcodes/enclosure')}`, { key })).status,
    ).toBe(500);
    expect(
      (
        await req('DELETE', `/machine/file/${encodeURIComponent('0:/gcodes/enclosure')}?recursive=true`, {
          key,
        })
      ).status,
    ).toBe(204);
    expect(
      (await req('DELETE', `/machine/file/${encodeURIComponent('0:/gcodes/enclosure')}`, { key })).status,
    ).toBe(404);
  });

  it('plugins: install, start, stop, uninstall', async () => {
    const key = await connect();
    const zip = 'PK\u0003\u0004....plugin.json{"id":"MyPlugin","name":"My plugin","version":"2.0"}';
    expect((await req('PUT', '/machine/plugin', { key, body: zip })).status).toBe(204);
    expect((sim.model['plugins'] as JsonObject)['MyPlugin']).toMatchObject({
      name: 'My plugin',
      version: '2.0',
    });
    expect((await req('PUT', '/machine/plugin', { key, body: 'not a zip' })).status).toBe(500);
    expect((await req('POST', '/machine/stopPlugin', { key, body: 'GCodeStats' })).status).toBe(204);
    expect(((sim.model['plugins'] as JsonObject)['GCodeStats'] as JsonObject)['pid']).toBe(-1);
    expect((await req('POST', '/machine/startPlugin', { key, body: 'GCodeStats' })).status).toBe(204);
    expect(
      ((sim.model['plugins'] as JsonObject)['GCodeStats'] as JsonObject)['pid'] as number,
    ).toBeGreaterThan(0);
    expect((await req('DELETE', '/machine/plugin', { key, body: 'MyPlugin' })).status).toBe(204);
    expect((sim.model['plugins'] as JsonObject)['MyPlugin']).toBeUndefined();
  });

  it('async codes answer at once and the reply comes as a message', async () => {
    const key = await connect();
    const { frames, h } = openSocket(key);
    h.message('OK');
    const r = await req('POST', '/machine/code?async=true', { key, body: 'M115' });
    expect(await r.text()).toBe('');
    const last = JSON.parse(frames[frames.length - 1]!) as JsonObject;
    expect(JSON.stringify(last['messages'])).toMatch(/FIRMWARE_NAME/);
  });
});
