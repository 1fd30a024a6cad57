import { afterEach, beforeEach, describe, expect, it, vi } from 'vitest';
import { DEMO_JOB_NAME, DEMO_PAUSE_MS, G2coreSimulator, demoPocket } from './simulator';

let sim: G2coreSimulator;

async function call(
  method: string,
  path: string,
  body?: unknown,
): Promise<{ status: number; body: unknown }> {
  const init: RequestInit = { method };
  if (body !== undefined) {
    init.body = JSON.stringify(body);
    init.headers = { 'Content-Type': 'application/json' };
  }
  const res = await sim.fetch(new Request(`http://sim${path}`, init), path);
  const text = await res.text();
  return { status: res.status, body: text ? (JSON.parse(text) as unknown) : null };
}

const q = (o: unknown) => encodeURIComponent(JSON.stringify(o));

beforeEach(() => {
  vi.useFakeTimers();
  sim = new G2coreSimulator({ id: 'g', name: 'G' });
});
afterEach(() => {
  sim.dispose();
  vi.useRealTimers();
});

describe('machine resource', () => {
  it('shallow listing, groups and keys in every form', async () => {
    const shallow = await call('GET', '/machine?shallow=true');
    expect(Object.keys((shallow.body as { value: object }).value)).toContain('g54');
    for (const p of ['/machine/x/vm', '/machine/xvm', '/machine/x.vm']) {
      expect((await call('GET', p)).body).toEqual({ value: 40000 });
    }
    expect((await call('GET', '/machine/ct')).body).toEqual({ value: 0.1 });
    expect((await call('GET', '/machine/stat')).body).toEqual({ value: 1 });
  });

  it('filter selects mixed objects and attributes; non-null values return only changes', async () => {
    const r = await call('GET', `/machine?filter=${q({ x: null, y: { jm: null }, ct: null })}`);
    const v = (r.body as { value: Record<string, unknown> }).value;
    expect(v.y).toEqual({ jm: 5000 });
    expect((v.x as { vm: number }).vm).toBe(40000);
    expect(v.ct).toBe(0.1);
    const changed = await call('GET', `/machine?filter=${q({ ct: 0.1, y: { jm: 1 } })}`);
    expect((changed.body as { value: unknown }).value).toEqual({ y: { jm: 5000 } });
  });

  it('PUT sets a value; read-only, unknown and out-of-range keys are refused with the design codes', async () => {
    expect(await call('PUT', '/machine/x/vm', 30000)).toEqual({ status: 200, body: { value: 30000 } });
    expect((await call('GET', '/machine/xvm')).body).toEqual({ value: 30000 });
    const ro = await call('PUT', '/machine/fb', 1);
    expect(ro.status).toBe(405);
    expect(ro.body).toMatchObject({ status: { code: 104, description: 'Parameter is read-only' } });
    expect((await call('PUT', '/machine/g92/x', 1)).status).toBe(405);
    expect((await call('PUT', '/machine/xyzzy', 1)).body).toMatchObject({ status: { code: 100 } });
    expect((await call('PUT', '/machine/xyzzy', 1)).status).toBe(404);
    const range = await call('PUT', '/machine/1/mi', 3);
    expect([range.status, (range.body as { status: { code: number } }).status.code]).toEqual([416, 110]);
    const g54 = await call('PUT', '/machine/g54', { x: 5 });
    expect(g54.body).toMatchObject({ value: { g54: { x: 5, y: 0 } } });
  });
});

describe('status reports', () => {
  it('default fields, select filter and changed-only filter', async () => {
    const all = (await call('GET', '/status_report')).body as Record<string, number>;
    expect(all).toMatchObject({ stat: 1, posx: 0, unit: 1, coor: 1 });
    const sel = (await call('GET', `/status_report?filter=${q({ posx: null, stat: null })}`)).body;
    expect(sel).toEqual({ posx: 0, stat: 1 });
    expect((await call('GET', `/status_report?filter=${q({ posx: 0, stat: 1 })}`)).body).toEqual({});
    const bad = await call('GET', `/status_report?filter=${q({ nope: null })}`);
    expect(bad.status).toBe(404);
  });
});

describe('operations', () => {
  it('runs a G1 move at the feed: pend/run → done, position interpolated', async () => {
    const post = await call('POST', '/operation', { optype: 'run', value: ['G21 G90', 'G1 X10 F600'] });
    expect(post.status).toBe(201);
    const id = post.body as number;
    await vi.advanceTimersByTimeAsync(500);
    const mid = (await call('GET', `/status_report?filter=${q({ posx: null, stat: null, vel: null })}`))
      .body as Record<string, number>;
    expect(mid.stat).toBe(5);
    expect(mid.posx).toBeGreaterThan(3);
    expect(mid.posx).toBeLessThan(7);
    expect(mid.vel).toBeCloseTo(600);
    expect((await call('GET', `/operation/${id}`)).body).toMatchObject({ opstate: 'run', line: 1 });
    await vi.advanceTimersByTimeAsync(700);
    expect((await call('GET', `/operation/${id}`)).body).toMatchObject({ opstate: 'done', line: 2 });
    expect((await call('GET', '/status_report')).body).toMatchObject({ posx: 10, stat: 3, vel: 0 });
  });

  it('feedhold, cycle start and kill', async () => {
    const id = (await call('POST', '/operation', { optype: 'run', value: 'G1 X50 F600\n' })).body as number;
    await vi.advanceTimersByTimeAsync(1000);
    expect((await call('PUT', `/operation/${id}`, { opstate: 'pause' })).body).toMatchObject({
      opstate: 'pause',
    });
    const held = (await call('GET', '/status_report')).body as Record<string, number>;
    expect(held.stat).toBe(6);
    await vi.advanceTimersByTimeAsync(2000);
    expect(((await call('GET', '/status_report')).body as Record<string, number>).posx).toBe(held.posx);
    await call('PUT', `/operation/${id}`, { opstate: 'run' });
    await vi.advanceTimersByTimeAsync(1000);
    const moving = (await call('GET', '/status_report')).body as Record<string, number>;
    expect(moving.stat).toBe(5);
    expect(moving.posx).toBeGreaterThan(held.posx!);
    const killed = await call('PUT', `/operation/${id}`, { opstate: 'kill' });
    expect(killed.body).toMatchObject({ opstate: 'error', error: { code: 207, description: 'Kill job' } });
    expect(((await call('GET', '/status_report')).body as Record<string, number>).stat).toBe(4);
    expect((await call('PUT', `/operation/${id}`, { opstate: 'pause' })).status).toBe(405);
  });

  it('refuses bad G-code (400), missing feed, soft limits after homing (405) and commands in alarm (410)', async () => {
    const bad = await call('POST', '/operation', { optype: 'run', value: ['G0 X1', 'G999'] });
    expect([bad.status, (bad.body as { status: { code: number } }).status.code]).toEqual([400, 131]);
    expect(
      (
        (await call('POST', '/operation', { optype: 'run', value: ['G1 X1'] })).body as {
          status: { code: number };
        }
      ).status.code,
    ).toBe(142);
    await call('POST', '/operation', { optype: 'run', value: ['G28.2 X0 Y0 Z0'] });
    await vi.advanceTimersByTimeAsync(20_000);
    expect((await call('GET', '/status_report')).body).toMatchObject({ stat: 3, mpox: 0, mpoz: 0 });
    const soft = await call('POST', '/operation', { optype: 'run', value: ['G0 X500'] });
    expect([soft.status, (soft.body as { status: { code: number } }).status.code]).toEqual([405, 222]);
    sim
      .controls()
      .find((c) => c.id === 'limit')!
      .run();
    const rejected = await call('POST', '/operation', { optype: 'run', value: ['G0 X1'] });
    expect([rejected.status, (rejected.body as { status: { code: number } }).status.code]).toEqual([
      410, 204,
    ]);
    await call('GET', '/machine/clear');
    expect(((await call('GET', '/status_report')).body as Record<string, number>).stat).toBe(3);
    sim
      .controls()
      .find((c) => c.id === 'panic')!
      .run();
    expect((await call('GET', '/machine/clear')).status).toBe(410);
  });

  it('an open interlock holds motion; once closed the job waits for cycle start', async () => {
    const id = (await call('POST', '/operation', { optype: 'run', value: ['G1 X50 F600'] })).body as number;
    await vi.advanceTimersByTimeAsync(500);
    const interlock = sim.controls().find((c) => c.id === 'interlock')!;
    interlock.run();
    const at = (await call('GET', '/status_report')).body as Record<string, number>;
    expect(at.stat).toBe(11);
    await vi.advanceTimersByTimeAsync(1000);
    expect(((await call('GET', '/status_report')).body as Record<string, number>).posx).toBe(at.posx);
    interlock.run();
    expect(((await call('GET', '/status_report')).body as Record<string, number>).stat).toBe(6);
    await call('PUT', `/operation/${id}`, { opstate: 'run' });
    await vi.advanceTimersByTimeAsync(500);
    expect(((await call('GET', '/status_report')).body as Record<string, number>).posx).toBeGreaterThan(
      at.posx!,
    );
  });

  it('homing searches for the switch (stat 9) and dwell waits', async () => {
    await call('POST', '/operation', { optype: 'run', value: ['G28.2 X0', 'G4 P1'] });
    await vi.advanceTimersByTimeAsync(200);
    expect(((await call('GET', '/status_report')).body as Record<string, number>).stat).toBe(9);
    // Search: 153 mm toward the switch (3 mm beyond X min) at sv 3000 mm/min.
    await vi.advanceTimersByTimeAsync(2600);
    const search = (await call('GET', '/status_report')).body as Record<string, number>;
    expect([search.stat, search.vel]).toEqual([9, 3000]);
    expect(search.mpox).toBeLessThan(-130);
    // Latch: off the switch at lv 100 mm/min.
    await vi.advanceTimersByTimeAsync(600);
    const latch = (await call('GET', '/status_report')).body as Record<string, number>;
    expect([latch.stat, latch.vel]).toEqual([9, 100]);
    // Zero backoff, then the axis stands at its home position (tn = 0) and the dwell runs.
    await vi.advanceTimersByTimeAsync(600);
    const s = (await call('GET', '/status_report')).body as Record<string, number>;
    expect(s.stat).toBe(5);
    expect(s.mpox).toBe(0);
    expect((await call('GET', `/status_report?filter=${q({ homx: null })}`)).body).toEqual({ homx: 1 });
    await vi.advanceTimersByTimeAsync(1000);
    expect(((await call('GET', '/status_report')).body as Record<string, number>).stat).toBe(3);
  });
});

describe('jobs', () => {
  it('queue, reorder, run with progress, kill', async () => {
    const a = (await call('POST', '/job', { name: 'a.nc', gcode: 'G21\nG1 X10 F600\nG1 X20\n' }))
      .body as number;
    const b = (await call('POST', '/job', { name: 'b.nc', gcode: 'G0 X1\n' })).body as number;
    await call('PUT', `/job/${b}`, { position: 0 });
    let list = (await call('GET', '/job')).body as { id: number; position: number }[];
    expect(list.map((j) => j.id)).toEqual([b, a]);
    const run = await call('PUT', `/job/${a}`, { state: 'run' });
    expect(run.body).toMatchObject({ state: 'running', lines: 3 });
    expect((await call('PUT', `/job/${b}`, { state: 'run' })).status).toBe(405);
    await vi.advanceTimersByTimeAsync(1500);
    const mid = (await call('GET', `/job/${a}`)).body as { done: number; state: string };
    expect(mid.done).toBeGreaterThanOrEqual(2);
    expect(mid.state).toBe('running');
    await call('PUT', `/job/${a}`, { state: 'kill' });
    expect((await call('GET', `/job/${a}`)).body).toMatchObject({ state: 'killed' });
    list = (await call('GET', '/job')).body as { id: number; position: number }[];
    expect(list[0]).toMatchObject({ id: b, position: 0 });
  });
});

describe('demo control', () => {
  type JobRow = { id: number; name: string; state: string; lines: number; done: number };
  const jobs = async () => (await call('GET', '/job')).body as JobRow[];
  const sr = async () => (await call('GET', '/status_report')).body as Record<string, number>;

  beforeEach(() => {
    sim.dispose();
    // One-second steps keep minutes of simulated cutting cheap; moves interpolate over the budget.
    sim = new G2coreSimulator({ id: 'g', name: 'G', tickMs: 1000 });
  });

  it('homes, then cuts a pocket job over several minutes that the console can hold and resume', async () => {
    const demo = sim.controls().find((c) => c.id === 'demo');
    expect(demo?.label).toBe('Start a demo job');
    demo!.run();
    demo!.run(); // a second press while it runs starts nothing new
    let list = await jobs();
    expect(list).toHaveLength(1);
    expect(list[0]).toMatchObject({ name: DEMO_JOB_NAME, state: 'running', lines: demoPocket().length });
    await vi.advanceTimersByTimeAsync(1000);
    expect((await sr()).stat).toBe(9); // homing first
    await vi.advanceTimersByTimeAsync(20_000);
    const s1 = await sr();
    expect(s1.stat).toBe(5);
    const done1 = (await jobs())[0]!.done;
    await vi.advanceTimersByTimeAsync(30_000);
    const s2 = await sr();
    expect([s2.posx, s2.posy]).not.toEqual([s1.posx, s1.posy]);
    expect(s2.posz).toBeLessThan(-20); // cutting below the stock top
    expect((await jobs())[0]!.done).toBeGreaterThan(done1);
    // The job is an ordinary job: the console holds and resumes it.
    const id = (await jobs())[0]!.id;
    expect((await call('PUT', `/job/${id}`, { state: 'pause' })).status).toBe(200);
    expect((await sr()).stat).toBe(6);
    await vi.advanceTimersByTimeAsync(5000);
    expect((await jobs())[0]!.state).toBe('paused');
    expect((await call('PUT', `/job/${id}`, { state: 'run' })).status).toBe(200);
    expect((await sr()).stat).toBe(5);
    list = await jobs();
    expect(list[0]!.done).toBeLessThan(list[0]!.lines);
  });

  it('runs for several minutes, then starts again after a pause; a kill ends the loop', async () => {
    sim
      .controls()
      .find((c) => c.id === 'demo')!
      .run();
    let seconds = 0;
    while ((await jobs())[0]!.state === 'running' && seconds < 900) {
      await vi.advanceTimersByTimeAsync(5000);
      seconds += 5;
    }
    expect(seconds).toBeGreaterThanOrEqual(180);
    expect(seconds).toBeLessThan(600);
    let list = await jobs();
    expect(list.map((j) => j.state)).toEqual(['done']);
    expect(list[0]!.done).toBe(list[0]!.lines);
    expect((await sr()).stat).toBe(4); // M30: program end
    await vi.advanceTimersByTimeAsync(DEMO_PAUSE_MS + 1000);
    list = await jobs();
    expect(list.map((j) => [j.name, j.state])).toEqual([
      [DEMO_JOB_NAME, 'running'],
      [DEMO_JOB_NAME, 'done'],
    ]);
    expect(sim.demoRunning).toBe(true);
    // The operator kills it: the machine stays stopped.
    expect((await call('PUT', `/job/${list[0]!.id}`, { state: 'kill' })).status).toBe(200);
    await vi.advanceTimersByTimeAsync(DEMO_PAUSE_MS * 3);
    expect((await jobs()).map((j) => j.state)).toEqual(['killed', 'done']);
    expect(sim.demoRunning).toBe(false);
  });

  it('waits for an alarm to be cleared and for other work to finish before it starts', async () => {
    sim
      .controls()
      .find((c) => c.id === 'limit')!
      .run();
    sim
      .controls()
      .find((c) => c.id === 'demo')!
      .run();
    await vi.advanceTimersByTimeAsync(2000);
    expect(await jobs()).toEqual([]);
    await call('GET', '/machine/clear');
    await vi.advanceTimersByTimeAsync(1000);
    expect((await jobs())[0]).toMatchObject({ name: DEMO_JOB_NAME, state: 'running' });
  });
});

describe('arcs', () => {
  const pos = async () => {
    const r = (await call('GET', `/status_report?filter=${q({ posx: null, posy: null, stat: null })}`))
      .body as Record<string, number>;
    return r;
  };

  it('G2 follows the circle (I/J centre), G3 with R goes the other way; bad arcs get the arc codes', async () => {
    expect(
      (await call('POST', '/operation', { optype: 'run', value: ['G2 X20 Y0 I10 J0 F600'] })).status,
    ).toBe(201);
    await vi.advanceTimersByTimeAsync(1600); // half of the 31.4 mm half circle at 600 mm/min
    const mid = await pos();
    expect(mid.posx).toBeCloseTo(10, 0);
    expect(mid.posy).toBeGreaterThan(9); // clockwise from the left: over the top
    await vi.advanceTimersByTimeAsync(2000);
    expect(await pos()).toEqual({ posx: 20, posy: 0, stat: 3 });
    await call('POST', '/operation', { optype: 'run', value: ['G3 X0 Y0 R10 F600'] });
    await vi.advanceTimersByTimeAsync(1600);
    expect((await pos()).posy).toBeGreaterThan(9); // counter-clockwise back from the right: over the top
    await vi.advanceTimersByTimeAsync(2000);
    expect(await pos()).toEqual({ posx: 0, posy: 0, stat: 3 });
    const noCentre = await call('POST', '/operation', { optype: 'run', value: ['G2 X20 Y0 F600'] });
    expect([noCentre.status, (noCentre.body as { status: { code: number } }).status.code]).toEqual([
      400, 157,
    ]);
    const radius = await call('POST', '/operation', { optype: 'run', value: ['G2 X20 Y0 I3 J0 F600'] });
    expect((radius.body as { status: { code: number } }).status.code).toBe(158);
  });
});

describe('operation list', () => {
  it('GET /operation lists the unfinished operations in order, then finished ones', async () => {
    await call('POST', '/operation', { optype: 'run', value: ['G0 X1'] });
    await vi.advanceTimersByTimeAsync(1000);
    const a = await call('POST', '/operation', { optype: 'run', value: ['G1 X100 F100'] });
    const b = await call('POST', '/operation', { optype: 'run', value: ['G1 X0 F100'] });
    const list = (await call('GET', '/operation')).body as { id: number; opstate: string }[];
    expect(list.map((o) => [o.id, o.opstate])).toEqual([
      [a.body, 'run'],
      [b.body, 'pend'],
      [42, 'done'],
    ]);
  });
});

describe('input limits', () => {
  it('a line longer than the line buffer is 413 with status 107', async () => {
    const r = await call('POST', '/operation', { optype: 'run', value: [`G0 X1 (${'x'.repeat(300)})`] });
    expect([r.status, (r.body as { status: { code: number } }).status.code]).toEqual([413, 107]);
  });
});

describe('sendfile', () => {
  it('runs a queued job like PUT /job/{id} run: refused behind other motion, then running with its operation', async () => {
    const job = (await call('POST', '/job', { name: 'a.nc', gcode: 'G1 X10 F600' })).body as number;
    await call('POST', '/operation', { optype: 'run', value: ['G1 X50 F600'] });
    const busy = await call('POST', '/operation', { optype: 'sendfile', value: job });
    expect([busy.status, (busy.body as { status: { code: number } }).status.code]).toEqual([405, 106]);
    await vi.advanceTimersByTimeAsync(6000);
    const ok = await call('POST', '/operation', { optype: 'sendfile', value: job });
    expect(ok.status).toBe(201);
    expect((await call('GET', `/job/${job}`)).body).toMatchObject({
      state: 'running',
      operation: ok.body,
      position: null,
    });
  });
});
