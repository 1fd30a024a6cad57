import { afterEach, describe, expect, it } from 'vitest';
import { SIM_MONITOR_API_KEY, TouchcutSimulator } from './simulator';

let sim: TouchcutSimulator;
let t = Date.parse('2026-03-18T10:00:00Z');
afterEach(() => sim.dispose());

function make() {
  t = Date.parse('2026-03-18T10:00:00Z');
  sim = new TouchcutSimulator({ id: 's', name: 'S', now: () => t, tickMs: 1_000_000 });
  sim.autoOperator = false;
  return sim;
}

const get = (path: string, headers: Record<string, string> = { 'X-TouchCut-API-Key': SIM_MONITOR_API_KEY }) =>
  sim.fetch(new Request(`http://x/machines/s${path}`, { headers }), path);

describe('touchcut simulator', () => {
  it('runs a cutting cycle: states, progress, moving torch, tool on, completion', async () => {
    make();
    sim.startProgram();
    const seen = new Set<string>();
    let lastX = -1;
    let moved = false;
    let toolOnSeen = false;
    for (let i = 0; i < 400; i++) {
      t += 1000;
      const s = (await (await get('/rest/v1/status')).json()) as Record<string, unknown>;
      seen.add(String(s.stateName));
      const x = (s.actualPos as { vec: number[] }).vec[0] ?? 0;
      if (lastX >= 0 && x !== lastX) moved = true;
      lastX = x;
      if (s.toolOn === true) toolOnSeen = true;
      if (s.programState === 'Complete') break;
    }
    expect([...seen]).toEqual(
      expect.arrayContaining(['Rapid Move', 'Piercing', 'Cutting', 'Program Complete']),
    );
    expect(moved).toBe(true);
    expect(toolOnSeen).toBe(true);
    expect(sim.live.starts).toBe(6);
  });

  it('draws a valid PNG that changes at most once per second', async () => {
    make();
    const a = new Uint8Array(await (await get('/rest/v1/screenshot')).arrayBuffer());
    expect(a.slice(12, 16)).toEqual(new Uint8Array([73, 72, 68, 82])); // IHDR
    t += 500;
    const b = new Uint8Array(await (await get('/rest/v1/screenshot')).arrayBuffer());
    expect(Buffer.from(b).equals(Buffer.from(a))).toBe(true);
    expect(sim.screenshotsDrawn).toBe(1);
    t += 600;
    await get('/rest/v1/screenshot');
    expect(sim.screenshotsDrawn).toBe(2);
  });

  it('answers unknown resources 404, sub paths 405, and accepts the JWT cookie', async () => {
    make();
    expect((await get('/rest/v1/nothing')).status).toBe(404);
    expect((await get('/rest/v1/monitor/axes')).status).toBe(405);
    const login = await sim.fetch(
      new Request('http://x/rest/v1/auth', {
        method: 'POST',
        body: JSON.stringify({ username: 'viewer', password: 'viewer' }),
      }),
      '/rest/v1/auth',
    );
    const { token } = (await login.json()) as { token: string };
    expect((await get('/rest/v1/status', { Cookie: `__Secure-jwt=${token}` })).status).toBe(200);
    // A JWT takes precedence over a key: a bad JWT is refused even with a good key.
    expect(
      (
        await get('/rest/v1/status', {
          Authorization: 'Bearer bad',
          'X-TouchCut-API-Key': SIM_MONITOR_API_KEY,
        })
      ).status,
    ).toBe(401);
  });

  it('control "demo" starts a job of several minutes that starts again, through its own state only', () => {
    make();
    const demo = sim.controls().find((c) => c.id === 'demo');
    expect(demo?.label).toBe('Start a demo job');
    sim.fault();
    demo?.run();
    expect(sim.status('metric', null).machineState).toBe('Running');
    expect(sim.status('metric', null).msgStatus).toEqual([]);
    const first = sim.programName;
    // Progresses over several minutes: after one minute it is well under way but far from done.
    t += 60_000;
    sim.advance();
    expect(sim.progress).toBeGreaterThan(5);
    expect(sim.progress).toBeLessThan(40);
    let completedAt = 0;
    for (let s = 60; s < 900 && !completedAt; s++) {
      t += 1000;
      sim.advance();
      if (sim.mode === 'complete') completedAt = s;
    }
    expect(completedAt).toBeGreaterThan(180);
    expect(sim.live.starts).toBe(12);
    // ... and starts again by itself.
    for (let i = 0; i < 20 && sim.mode !== 'running'; i++) {
      t += 1000;
      sim.advance();
    }
    expect(sim.mode).toBe('running');
    expect(sim.programName).not.toBe(first);
    expect(sim.progress).toBeLessThan(10);
    // Never a request: the simulator's own state only.
    expect(sim.requests).toHaveLength(0);
    // Running it again while a job runs leaves that job alone.
    const p = sim.progress;
    const name = sim.programName;
    demo?.run();
    expect(sim.programName).toBe(name);
    expect(sim.progress).toBe(p);
  });
});
