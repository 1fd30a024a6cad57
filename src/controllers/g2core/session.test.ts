import { setupServer } from 'msw/node';
import { afterAll, afterEach, beforeAll, beforeEach, describe, expect, it, vi } from 'vitest';
import { CommandRefused } from '../../fleet/commands';
import { createContext } from '../../fleet/fleet';
import { alwaysVisible } from '../../fleet/link';
import { simulatorHandlers } from '../../fleet/msw';
import type { Role } from '../../fleet/types';
import { G2coreSession } from './session';
import { G2coreSimulator } from './sim/simulator';

let sim: G2coreSimulator;
const server = setupServer();
let role: Role = 'supervisor';

beforeAll(() => server.listen({ onUnhandledRequest: 'error' }));
afterAll(() => server.close());
beforeEach(() => {
  vi.useFakeTimers();
  role = 'supervisor';
  sim = new G2coreSimulator({ id: 'cnc', name: 'CNC' });
  server.resetHandlers(...simulatorHandlers('cnc', sim));
});
afterEach(() => {
  sim.dispose();
  vi.useRealTimers();
});

function makeSession(detail: () => boolean = () => true) {
  const ctx = createContext(
    { id: 'cnc', name: 'CNC', kind: 'g2core', simulated: true },
    { visibility: alwaysVisible, principal: () => ({ name: 'tester', role }), detail },
  );
  const s = new G2coreSession(ctx);
  s.start();
  return s;
}

const settle = async (ms = 600) => {
  await vi.advanceTimersByTimeAsync(ms);
};

describe('G2coreSession through msw', () => {
  it('connects, reads the version and axes, and fills the snapshot', async () => {
    const s = makeSession();
    await settle();
    const snap = s.ctx.snapshot.getState();
    expect(snap.link).toBe('online');
    expect(snap.activity).toBe('idle');
    expect(snap.activityLabel).toBe('Ready');
    expect(snap.identity).toContain('100.12-14-g375c-dirty');
    expect(Object.keys(snap.positions)).toEqual(['X', 'Y', 'Z']);
    expect(s.detail.getState().axes).toEqual(['x', 'y', 'z']);
    s.stop();
  });

  it('polls with the changed-only filter after the first full report', async () => {
    const seen: string[] = [];
    const inner = sim.fetch.bind(sim);
    sim.fetch = (req, path) => {
      if (path.startsWith('/status_report')) seen.push(path);
      return inner(req, path);
    };
    const s = makeSession();
    await settle(1100);
    expect(seen[0]).toBe('/status_report');
    expect(seen.length).toBeGreaterThanOrEqual(4);
    const filter = JSON.parse(new URLSearchParams(seen[1]!.split('?')[1]).get('filter')!) as Record<
      string,
      unknown
    >;
    expect(filter).toMatchObject({ stat: 1, posx: 0 });
    s.stop();
  });

  it('reads status 4 times a second for its machine page, once a second for a fleet tile alone', async () => {
    let reads = 0;
    const inner = sim.fetch.bind(sim);
    sim.fetch = (req, path) => {
      if (path.startsWith('/status_report')) reads++;
      return inner(req, path);
    };
    let pageOpen = false;
    const s = makeSession(() => pageOpen);
    await settle(1000);
    reads = 0;
    await settle(10_000);
    expect(reads).toBeGreaterThanOrEqual(9);
    expect(reads).toBeLessThanOrEqual(11);
    pageOpen = true;
    await settle(1000);
    reads = 0;
    await settle(10_000);
    expect(reads).toBeGreaterThanOrEqual(38);
    expect(s.ctx.snapshot.getState().link).toBe('online');
    s.stop();
  });

  it('jogs, follows the position, and the big stop kills the jog', async () => {
    const s = makeSession();
    await settle();
    await s.ctx.commands.run(s.jog, { axis: 'x', distance: 100, feed: 600 });
    await settle(2000);
    const snap = s.ctx.snapshot.getState();
    expect(snap.activity).toBe('running');
    expect(snap.positions.X).toBeGreaterThan(10);
    expect(snap.positions.X).toBeLessThan(40);
    expect(s.ctx.commands.blockedReason(s.stopJog)).toBeNull();
    await s.ctx.commands.run(s.stopJog, undefined);
    await settle();
    const x = s.ctx.snapshot.getState().positions.X!;
    await settle(1000);
    expect(s.ctx.snapshot.getState().positions.X).toBe(x);
    expect(s.detail.getState().sr.stat).toBe(4);
    expect(s.detail.getState().sr.dist).toBe(0);
    s.stop();
  });

  it('MDI refusals carry the status text; errors at run time reach the console', async () => {
    const s = makeSession();
    await settle();
    await expect(s.ctx.commands.run(s.mdi, { text: 'G1 X10' })).rejects.toThrow(/Feedrate not specified/);
    const entry = s.detail.getState().console.at(-1)!;
    expect(entry.state).toBe('refused');
    expect(entry.message).toContain('Feedrate not specified');
    await s.ctx.commands.run(s.mdi, { text: 'G21\nG4 P0.5\n{xvm:null}' });
    await settle(1500);
    expect(s.detail.getState().console.at(-1)).toMatchObject({ state: 'done', message: '{"xvm":40000}' });
    s.stop();
  });

  it('runs a job with progress, holds, resumes and kills it', async () => {
    const s = makeSession();
    await settle();
    const gcode = ['G21', 'G90', 'G1 X10 F600', 'G1 X20', 'G1 X30', 'G1 X40'].join('\n');
    await s.ctx.commands.run(s.queueJob, { name: 'part.nc', gcode });
    await settle(50); // the queue is read again right after the command (kick), not inside it
    const job = s.detail.getState().jobs[0]!;
    expect(job).toMatchObject({ name: 'part.nc', lines: 6 });
    await s.ctx.commands.run(s.runJob, { id: job.id, name: 'part.nc' });
    await settle(2500);
    let snap = s.ctx.snapshot.getState();
    expect(snap.activity).toBe('running');
    expect(snap.job?.name).toBe('part.nc');
    expect(snap.job?.progress).toBeGreaterThan(0.3);
    expect(snap.job?.progress).toBeLessThan(1);
    await s.ctx.commands.run(s.feedhold, undefined);
    await settle();
    snap = s.ctx.snapshot.getState();
    expect(snap.activity).toBe('paused');
    const held = snap.positions.X;
    await settle(1000);
    expect(s.ctx.snapshot.getState().positions.X).toBe(held);
    await s.ctx.commands.run(s.resume, undefined);
    await settle(600);
    expect(s.ctx.snapshot.getState().positions.X).toBeGreaterThan(held!);
    await s.ctx.commands.run(s.kill, undefined);
    await settle(1200);
    expect(s.detail.getState().jobs[0]!.state.state).toBe('killed');
    expect(s.ctx.snapshot.getState().activity).toBe('idle');
    expect(s.ctx.snapshot.getState().job).toBeNull();
    s.stop();
  });

  it('queues an uploaded file (multipart) and a runtime soft limit alarms the machine', async () => {
    const s = makeSession();
    await settle();
    await s.ctx.commands.run(s.home, { axes: ['x'] });
    await settle(4000);
    expect(s.detail.getState().sr.stat).toBe(3);
    const file = new Blob(['G21 G90\nG0 X10\nG0 X900\n'], { type: 'text/plain' });
    await s.ctx.commands.run(s.queueJob, { name: 'too-far.nc', file });
    await settle(50); // the queue is read again right after the command (kick), not inside it
    const job = s.detail.getState().jobs[0]!;
    expect(job).toMatchObject({ name: 'too-far.nc', lines: 3 });
    await s.ctx.commands.run(s.runJob, { id: job.id, name: 'too-far.nc' });
    await settle(1500);
    expect(s.detail.getState().jobs[0]!.state.state).toBe('error');
    const snap = s.ctx.snapshot.getState();
    expect(snap.activity).toBe('alarm');
    expect(snap.alarms[0]!.message).toContain('Soft limit - X max');
    s.stop();
  });

  it('alarm shows what clears it; clear alarm brings the machine back', async () => {
    const s = makeSession();
    await settle();
    sim
      .controls()
      .find((c) => c.id === 'limit')!
      .run();
    await settle();
    const snap = s.ctx.snapshot.getState();
    expect(snap.activity).toBe('alarm');
    expect(snap.alarms[0]).toMatchObject({ id: 'g2core-alarm', severity: 'critical' });
    expect(snap.alarms[0]!.clears).toMatch(/Clear alarm/);
    expect(s.ctx.commands.blockedReason(s.jog)).toMatch(/alarm/i);
    await s.ctx.commands.run(s.clearAlarm, undefined);
    await settle();
    expect(s.ctx.snapshot.getState().alarms).toEqual([]);
    sim
      .controls()
      .find((c) => c.id === 'panic')!
      .run();
    await settle();
    expect(s.ctx.snapshot.getState().alarms[0]!.clears).toMatch(/power cycle/);
    expect(s.ctx.commands.blockedReason(s.clearAlarm)).toMatch(/PANIC/);
    s.stop();
  });

  it('settings: edits, read-only and range refusals with the status text', async () => {
    const s = makeSession();
    await settle();
    // Settings are on-demand reads (query layer): the write makes the group stale, so the next
    // read of it asks the controller again.
    expect(await s.loadGroups()).toContain('he1');
    expect((await s.loadGroup('x')).vm).toBe(40000);
    await s.ctx.commands.run(s.setSetting, { group: 'x', key: 'vm', value: 25000 });
    expect((await s.loadGroup('x')).vm).toBe(25000);
    expect(await s.client.getKey('x', 'vm')).toBe(25000);
    await expect(s.ctx.commands.run(s.setSetting, { group: 'g92', key: 'x', value: 1 })).rejects.toThrow(
      /read-only/,
    );
    expect(s.settings.getState().fieldErrors['g92.x']).toContain('Parameter is read-only');
    expect(s.settings.getState().refusedReadOnly['g92.x']).toBe(true);
    await expect(s.ctx.commands.run(s.setSetting, { group: 'sys', key: 'si', value: 5 })).rejects.toThrow(
      /less than minimum/,
    );
    s.stop();
  });

  it('an operator may not change settings; nothing is sent while offline', async () => {
    role = 'operator';
    const s = makeSession();
    await settle();
    await expect(
      s.ctx.commands.run(s.setSetting, { group: 'x', key: 'vm', value: 1 }),
    ).rejects.toBeInstanceOf(CommandRefused);
    s.stop();
    s.ctx.snapshot.setState({ link: 'offline' });
    role = 'supervisor';
    await expect(s.ctx.commands.run(s.jog, { axis: 'x', distance: 1, feed: 100 })).rejects.toBeInstanceOf(
      CommandRefused,
    );
  });

  it('a malformed status report becomes a protocol error with the path', async () => {
    const inner = sim.fetch.bind(sim);
    sim.fetch = async (req, path) =>
      path.startsWith('/status_report')
        ? new Response(JSON.stringify({ posx: { bad: true } }), { status: 200 })
        : inner(req, path);
    const s = makeSession();
    await settle();
    const snap = s.ctx.snapshot.getState();
    expect(snap.link).toBe('protocol-error');
    expect(snap.problem?.path).toBe('posx');
    s.stop();
  });
  it('finds motion another console started (GET /operation) and holds and kills it', async () => {
    const s = makeSession();
    await settle();
    // Another console runs a long move: this session started nothing.
    const res = await sim.fetch(
      new Request('http://sim/operation', {
        method: 'POST',
        body: JSON.stringify({ optype: 'run', value: ['G1 X200 F300'] }),
      }),
      '/operation',
    );
    const id = String(await res.json());
    await settle(2500);
    expect(s.ctx.snapshot.getState().activity).toBe('running');
    expect(s.feedhold.available?.(s.ctx.snapshot.getState())).toBe(true);
    expect(s.detail.getState().ops[id]?.label).toContain('started elsewhere');
    await s.ctx.commands.run(s.feedhold, undefined);
    await settle();
    expect(sim.stat).toBe(6);
    await s.ctx.commands.run(s.kill, undefined);
    await settle();
    expect(sim.stat).toBe(4);
    const op = (await (
      await sim.fetch(new Request(`http://sim/operation/${id}`), `/operation/${id}`)
    ).json()) as {
      opstate: string;
      error: { code: number };
    };
    expect([op.opstate, op.error.code]).toEqual(['error', 207]);
    s.stop();
  });

  it('says so when the server cannot list operations', async () => {
    const inner = sim.fetch.bind(sim);
    sim.fetch = (req, path) =>
      path === '/operation' && req.method === 'GET'
        ? Promise.resolve(
            new Response(
              JSON.stringify({ status: { code: 100, description: 'Unrecognized command or config name' } }),
              {
                status: 404,
                headers: { 'Content-Type': 'application/json' },
              },
            ),
          )
        : inner(req, path);
    const s = makeSession();
    await settle();
    await inner(
      new Request('http://sim/operation', {
        method: 'POST',
        body: JSON.stringify({ optype: 'run', value: 'G1 X200 F300' }),
      }),
      '/operation',
    );
    await settle(2500);
    expect(s.opsListSupported).toBe(false);
    expect(s.feedhold.available?.(s.ctx.snapshot.getState())).toMatch(/cannot list its operations/);
    s.stop();
  });
  it('MDI waits for no job: refused while a job runs, allowed behind its own lines', async () => {
    const s = makeSession();
    await settle();
    await s.ctx.commands.run(s.mdi, { text: 'G1 X50 F300' });
    await settle(1500);
    expect(s.ctx.snapshot.getState().activity).toBe('running');
    expect(s.mdi.available?.(s.ctx.snapshot.getState())).toBe(true);
    await s.ctx.commands.run(s.kill, undefined);
    await settle();
    await s.ctx.commands.run(s.queueJob, { name: 'long.nc', gcode: 'G1 X100 F300' });
    await settle(50); // the queue is read again right after the command (kick), not inside it
    const job = s.detail.getState().jobs[0]!;
    await s.ctx.commands.run(s.runJob, { id: job.id, name: 'long.nc' });
    await settle(1500);
    expect(s.mdi.available?.(s.ctx.snapshot.getState())).toMatch(/Not while job "long.nc" runs/);
    await expect(s.ctx.commands.run(s.mdi, { text: 'G0 X0' })).rejects.toThrow();
    s.stop();
  });
  it('the big STOP also stops a job in motion (homing inside the demo job)', async () => {
    const s = makeSession();
    await settle();
    expect(s.ctx.commands.blockedReason(s.stopJog)).toBe('Nothing is moving');
    sim
      .controls()
      .find((c) => c.id === 'demo')!
      .run();
    await settle(1500);
    expect(sim.stat).toBe(9);
    expect(s.ctx.commands.blockedReason(s.stopJog)).toBeNull();
    await s.ctx.commands.run(s.stopJog, undefined);
    await settle();
    expect(sim.stat).toBe(4);
    expect(s.detail.getState().jobs[0]?.state.state).toBe('killed');
    s.stop();
  });

  it('a serial board the gateway reports stuck in run: a supervisor may reset it (POST /board/reset), nobody else', async () => {
    const resets: string[] = [];
    let stuck = false;
    const inner = sim.fetch.bind(sim);
    sim.fetch = async (req, path) => {
      if (path === '/board/reset' && req.method === 'POST') {
        resets.push(req.headers.get('x-shopdeck-command') ?? '');
        stuck = false;
        return Response.json({ value: 'reset sent' });
      }
      if (stuck && path.startsWith('/status_report'))
        return Response.json(
          {
            error:
              'CNC: the board has sent nothing since line 42 while running (stuck in run). A supervisor can reset the board',
            gateway: true,
          },
          { status: 503, headers: { 'X-Shopdeck-Gateway': 'error' } },
        );
      return inner(req, path);
    };
    const s = makeSession();
    await settle();
    expect(s.ctx.commands.blockedReason(s.resetBoard)).toMatch(/stuck in run/);
    await expect(s.ctx.commands.run(s.resetBoard, undefined)).rejects.toBeInstanceOf(CommandRefused);
    stuck = true;
    await settle(2000);
    expect(s.ctx.snapshot.getState().problem?.message).toContain('stuck in run');
    role = 'operator';
    expect(s.ctx.commands.blockedReason(s.resetBoard)).not.toBeNull();
    await expect(s.ctx.commands.run(s.resetBoard, undefined)).rejects.toBeInstanceOf(CommandRefused);
    expect(resets).toEqual([]);
    role = 'supervisor';
    expect(s.ctx.commands.blockedReason(s.resetBoard)).toBeNull();
    await s.ctx.commands.run(s.resetBoard, undefined);
    expect(resets.length).toBe(1);
    expect(resets[0]).not.toBe('');
    s.stop();
  });
});
