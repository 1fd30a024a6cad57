import { setupServer } from 'msw/node';
import { afterAll, afterEach, beforeAll, beforeEach, describe, expect, it, vi } from 'vitest';
import { CommandRefused, commandHistory, confirmationText, type Principal } from '../../fleet/commands';
import { createContext } from '../../fleet/fleet';
import { alwaysVisible } from '../../fleet/link';
import { simulatorHandlers } from '../../fleet/msw';
import { FaultySimulator, jsonResponse, type Simulator } from '../../fleet/sim';
import type { Role } from '../../fleet/types';
import { POLL_BUSY_MS, POLL_IDLE_MS, RECHECK_MAX_MS, SETTINGS_REFRESH_MS, XtoolSession } from './session';
import { XtoolSimulator } from './sim/simulator';

const server = setupServer();
beforeAll(() => server.listen({ onUnhandledRequest: 'error' }));
afterAll(() => server.close());

let seq = 0;
let session: XtoolSession | null = null;
let sim: XtoolSimulator | null = null;

beforeEach(() => {
  vi.useFakeTimers({ toFake: ['setTimeout', 'clearTimeout', 'setInterval', 'clearInterval', 'Date'] });
});
afterEach(() => {
  session?.stop();
  sim?.dispose();
  session = null;
  sim = null;
  server.resetHandlers();
  vi.useRealTimers();
});

/** A simulated laser behind msw and a session talking to it, as `role`. */
function setup(opts: { role?: Role; wrap?: (s: XtoolSimulator) => Simulator } = {}) {
  const id = `laser-${++seq}`;
  sim = new XtoolSimulator({ id, name: 'Test laser' });
  const served = opts.wrap ? opts.wrap(sim) : sim;
  server.use(...simulatorHandlers(id, served));
  const principal = (): Principal => ({ name: 'tester', role: opts.role ?? 'supervisor' });
  const ctx = createContext(
    { id, name: 'Test laser', kind: 'xtool', simulated: true },
    {
      visibility: alwaysVisible,
      principal,
    },
  );
  session = new XtoolSession(ctx);
  return { sim, session, ctx, served };
}

/** Let timers, requests and socket frames run for `ms` of simulated time. */
async function advance(ms: number): Promise<void> {
  const step = 50;
  for (let t = 0; t < ms; t += step) await vi.advanceTimersByTimeAsync(step);
}

/** Advance until the condition holds (in simulated time). */
async function until(cond: () => boolean, maxMs = 15_000): Promise<void> {
  for (let t = 0; t < maxMs && !cond(); t += 50) await vi.advanceTimersByTimeAsync(50);
  expect(cond()).toBe(true);
}

describe('XtoolSession against the simulator', () => {
  it('connects: identity, idle, online, socket open', async () => {
    const { session, ctx } = setup();
    session.start();
    await until(() => ctx.snapshot.getState().link === 'online' && session.detail.getState().socketOpen);
    const snap = ctx.snapshot.getState();
    expect(snap.activity).toBe('idle');
    expect(snap.identity).toBe('xTool D1Pro · 10 W · V40.31.006.01 B2');
    const d = session.detail.getState();
    expect(d.model.family).toBe('d-series');
    expect(d.identity).toMatchObject({
      name: 'My xTool D1 Pro',
      mac: '02:00:00:5E:00:01',
      sn: 'SIM0000000000001',
    });
    expect(d.periphery).toMatchObject({ sdCard: true, flameAlarmSensitivity: 1 });
    // Quirk: before any job the firmware sends strings; the client turned them into numbers.
    expect(d.progress).toEqual({ progress: 0, working: 0, line: 0 });
    expect(session.client.maxInFlight).toBe(1);
  });

  it('an operator pauses, resumes and stops a job started with the button', async () => {
    const { sim, session, ctx } = setup({ role: 'operator' });
    session.start();
    await until(() => session.detail.getState().socketOpen);
    sim.loadDemoJob();
    await until(() => session.detail.getState().machine.state === 'job-loaded');
    expect(ctx.snapshot.getState().activityLabel).toMatch(/press the button on the machine/);
    expect(ctx.commands.blockedReason(session.pause)).toBe('No job is running');

    sim.pressButton();
    await until(() => ctx.snapshot.getState().activity === 'running');
    await advance(POLL_BUSY_MS + 500);
    const running = ctx.snapshot.getState();
    expect(running.job?.progress).toBeGreaterThan(0);
    expect(running.job?.elapsed).toBeGreaterThan(0);
    expect(session.detail.getState().machine.startedBy).toBe('button');

    await ctx.commands.run(session.pause, undefined);
    await until(() => ctx.snapshot.getState().activity === 'paused');
    expect(sim.mode).toBe('paused');
    const line = sim.job?.line;
    await advance(2000);
    expect(sim.job?.line).toBe(line);

    await ctx.commands.run(session.resume, undefined);
    await until(() => ctx.snapshot.getState().activity === 'running');
    expect(confirmationText(session.stopJob, undefined)).toMatch(/Stop the job/);
    await ctx.commands.run(session.stopJob, undefined);
    await until(() => ctx.snapshot.getState().activity === 'stopping');
    await until(() => ctx.snapshot.getState().activity === 'idle');
    expect(session.client.maxInFlight).toBe(1);
  });

  it("the simulator's demo control shows as a job loaded, then running from the button", async () => {
    const { sim, session, ctx } = setup({ role: 'viewer' });
    session.start();
    await until(() => session.detail.getState().socketOpen);
    const demo = sim.controls().find((c) => c.id === 'demo');
    expect(demo?.label).toBe('Start a demo job');
    demo?.run();
    await until(() => session.detail.getState().machine.state === 'job-loaded');
    await until(() => ctx.snapshot.getState().activity === 'running');
    expect(session.detail.getState().machine.startedBy).toBe('button');
    // The vendor app's upload is /tmp.gcode (filetype 1).
    expect(ctx.snapshot.getState().job?.name).toBe('tmp.gcode');
    await advance(60_000);
    const snap = ctx.snapshot.getState();
    expect(snap.activity).toBe('running');
    expect(snap.job?.progress).toBeGreaterThan(0.1);
    expect(snap.job?.progress).toBeLessThan(0.5);
    expect(snap.job?.remaining).toBeGreaterThan(60);
    // Nothing went through the console: no command was run.
    expect(commandHistory.getState().records.filter((r) => r.machineId === ctx.machine.id)).toEqual([]);
  });

  it('polls every 3 s, busy or idle (the poll is the liveness: issue 15)', async () => {
    const { sim, session } = setup();
    session.start();
    await until(() => session.detail.getState().socketOpen);
    const before = session.poller.started;
    await advance(POLL_IDLE_MS * 2 + 100);
    expect(session.poller.started - before).toBe(2);
    sim.loadDemoJob();
    sim.pressButton();
    await until(() => session.detail.getState().machine.state === 'running');
    const mid = session.poller.started;
    await advance(POLL_BUSY_MS * 3 + 100);
    expect(session.poller.started - mid).toBeGreaterThanOrEqual(3);
    expect(session.poller.started - mid).toBeLessThanOrEqual(4);
  });

  it('a flame blocks until acknowledged', async () => {
    const { sim, session, ctx } = setup({ role: 'operator' });
    session.start();
    await until(() => session.detail.getState().socketOpen);
    sim.loadDemoJob();
    sim.pressButton();
    await until(() => ctx.snapshot.getState().activity === 'running');
    expect(sim.trip('flame')).toBe(true);
    await until(() => ctx.snapshot.getState().alarms.length === 1);
    const alarm = ctx.snapshot.getState().alarms[0];
    expect(alarm).toMatchObject({ id: 'xtool-flame', severity: 'critical', blocking: true });
    expect(ctx.snapshot.getState().activity).toBe('alarm');
    // Polls (the laser is idle now) do not clear the alarm.
    await advance(POLL_IDLE_MS + 500);
    expect(ctx.snapshot.getState().alarms).toHaveLength(1);
    session.acknowledgeAlarm('xtool-flame');
    expect(ctx.snapshot.getState().alarms).toHaveLength(0);
    expect(ctx.log.store.getState().entries.some((e) => /Alarm acknowledged/.test(e.text))).toBe(true);
  });

  it('re-reads the safety settings while idle, so a change made elsewhere shows', async () => {
    const { sim, session, ctx } = setup();
    session.start();
    await until(() => ctx.snapshot.getState().link === 'online');
    expect(session.detail.getState().periphery?.flameAlarmSensitivity).toBe(1);
    // Someone turns the flame alarm off with the vendor app, and pulls the SD card.
    sim.periphery.flameAlarmSensitivity = 3;
    sim.sdCard = false;
    await advance(SETTINGS_REFRESH_MS + POLL_IDLE_MS + 500);
    expect(session.detail.getState().periphery).toMatchObject({ flameAlarmSensitivity: 3, sdCard: false });
    expect(session.client.maxInFlight).toBe(1);
  });

  it('a sensor that is switched off does not trip', async () => {
    const { sim, session, ctx } = setup();
    session.start();
    await until(() => ctx.snapshot.getState().link === 'online');
    await ctx.commands.run(session.tiltStopOff, undefined);
    // The command made the settings stale: read again at once where shown (session.kernel.test.ts),
    // else by the next idle poll.
    await until(() => session.detail.getState().periphery?.tiltStopFlag === false, POLL_IDLE_MS + 500);
    expect(sim.trip('tilt')).toBe(false);
    await ctx.commands.run(session.tiltStopOn, undefined);
    await until(() => session.detail.getState().periphery?.tiltStopFlag === true, POLL_IDLE_MS + 500);
  });

  it('uploads a job, verifies it with /list and says the button starts it', async () => {
    const { session, ctx } = setup({ role: 'operator' });
    session.start();
    await until(() => ctx.snapshot.getState().link === 'online');
    const file = new Blob(['G90\nG1 X10 S100\nG1 Y10\n'], { type: 'text/plain' });
    const msg = await ctx.commands.run(session.upload, {
      file,
      name: 'coaster.gcode',
      target: { kind: 'job' },
    });
    expect(msg).toMatch(/starts with the button on the machine/);
    expect(session.detail.getState().upload).toMatchObject({ phase: 'done', path: '/tmp.gcode' });
    await until(() => session.detail.getState().machine.state === 'job-loaded');
    expect(ctx.snapshot.getState().job?.name).toBe('coaster.gcode');
    // The name is forgotten when the laser is idle again: the next job is not "coaster.gcode".
    await ctx.commands.run(session.stopJob, undefined);
    await until(() => session.detail.getState().machine.state === 'idle');
    expect(session.detail.getState().jobName).toBeNull();
  });

  it('catches the lying "ok" of a failed upload', async () => {
    const { sim, session, ctx } = setup({ role: 'operator' });
    session.start();
    await until(() => ctx.snapshot.getState().link === 'online');
    sim.uploadLies = true;
    const file = new Blob(['G1 X1\n']);
    const target = { kind: 'path' as const, filename: '/jobs/new.gcode' };
    await expect(ctx.commands.run(session.upload, { file, name: 'new.gcode', target })).rejects.toThrow(
      /not on the SD card/,
    );
    expect(session.detail.getState().upload?.phase).toBe('failed');
    expect(sim.files.has('/jobs/new.gcode')).toBe(false);
    sim.uploadLies = false;
    await ctx.commands.run(session.upload, { file, name: 'new.gcode', target });
    expect(sim.files.has('/jobs/new.gcode')).toBe(true);
  });

  it('catches the lying "ok" when a file of the same name was already on the card', async () => {
    const { sim, session, ctx } = setup({ role: 'operator' });
    session.start();
    await until(() => ctx.snapshot.getState().link === 'online');
    expect(sim.files.has('/tmp.gcode')).toBe(true);
    sim.uploadLies = true;
    const file = new Blob(['G1 X1\n']);
    await expect(
      ctx.commands.run(session.upload, { file, name: 'new.gcode', target: { kind: 'job' } }),
    ).rejects.toThrow(/did not load/);
    expect(sim.mode).toBe('idle');
  });

  it('reports a refused job action ("fail" with HTTP 200) as a failure', async () => {
    const { session, ctx } = setup();
    session.start();
    await until(() => ctx.snapshot.getState().link === 'online');
    // Bypass availability: the firmware itself refuses to pause an idle laser.
    await expect(session.client.jobAction('pause', 'xtool.pause')).rejects.toThrow(/refused/);
  });

  it('a powered-off laser is offline, and comes back', async () => {
    const { session, ctx, served } = setup({ wrap: (s) => new FaultySimulator(s) });
    const faulty = served as FaultySimulator;
    session.start();
    await until(() => ctx.snapshot.getState().link === 'online' && session.detail.getState().socketOpen);
    faulty.setFaults({ drop: true });
    faulty.closeSockets();
    await until(() => ctx.snapshot.getState().link === 'offline', 30_000);
    expect(ctx.snapshot.getState().activity).toBe('offline');
    await expect(ctx.commands.run(session.pause, undefined)).rejects.toBeInstanceOf(CommandRefused);
    faulty.setFaults({ drop: false });
    await until(() => ctx.snapshot.getState().link === 'online', 60_000);
    expect(ctx.snapshot.getState().activity).toBe('idle');
  });
});

describe('link and firmware', () => {
  it('a malformed (cut) answer is a failed request, not a verdict: the link is down, then back', async () => {
    const { session, ctx, served } = setup({ wrap: (s) => new FaultySimulator(s) });
    session.start();
    await until(() => ctx.snapshot.getState().link === 'online');
    (served as FaultySimulator).setFaults({ malformed: true });
    await until(() => ctx.snapshot.getState().link === 'offline', 30_000);
    expect(ctx.snapshot.getState().problem).toMatchObject({ kind: 'network' });
    expect(ctx.snapshot.getState().problem?.message).toMatch(/cut off.*not JSON/);
    (served as FaultySimulator).setFaults({ malformed: false });
    await until(() => ctx.snapshot.getState().link === 'online', 5000);
    // A whole answer of another shape is a protocol error naming its path: faults.test.ts.
  });

  it('polls at most every 10 s while the page is hidden, even with a job running', async () => {
    const id = `laser-${++seq}`;
    sim = new XtoolSimulator({ id, name: 'Hidden' });
    server.use(...simulatorHandlers(id, sim));
    const hidden = { hidden: () => true, subscribe: () => () => undefined };
    const ctx = createContext({ id, name: 'Hidden', kind: 'xtool', simulated: true }, { visibility: hidden });
    session = new XtoolSession(ctx);
    session.start();
    await until(() => session?.detail.getState().socketOpen === true);
    sim.loadDemoJob();
    sim.pressButton();
    await until(() => session?.detail.getState().machine.state === 'running');
    const before = session.poller.started;
    await advance(30_000);
    expect(session.poller.started - before).toBeLessThanOrEqual(3);
    expect(session.poller.started - before).toBeGreaterThanOrEqual(2);
  });

  it('firmware: OK is accepted, FAIL is reported', async () => {
    const { session, ctx } = setup();
    session.start();
    await until(() => ctx.snapshot.getState().link === 'online');
    const good = { file: new Blob([new Uint8Array([1, 2, 3])]), name: 'fw.bin' };
    await expect(ctx.commands.run(session.upgrade, good)).resolves.toBe('firmware accepted');
    const bad = { file: new Blob(['not firmware']), name: 'notes.txt' };
    await expect(ctx.commands.run(session.upgrade, bad)).rejects.toThrow(/FAIL/);
    expect(session.detail.getState().upgrade?.phase).toBe('failed');
  });
});

describe('roles and confirmation', () => {
  it('remote start is dangerous, supervisor only, and says it fires the laser unattended', async () => {
    const { session, ctx } = setup({ role: 'operator' });
    session.start();
    await until(() => ctx.snapshot.getState().link === 'online');
    expect(session.runFile.hazard).toBe('dangerous');
    expect(confirmationText(session.runFile, { path: '/tmp.gcode' })).toMatch(
      /without anyone at the machine/,
    );
    await expect(ctx.commands.run(session.runFile, { path: '/tmp.gcode' })).rejects.toThrow(/supervisor/);
    expect(sim?.mode).toBe('idle');
    await expect(ctx.commands.run(session.gcode, { code: 'M28' })).rejects.toBeInstanceOf(CommandRefused);
    await expect(ctx.commands.run(session.flameAlarmOff, undefined)).rejects.toBeInstanceOf(CommandRefused);
  });

  it('a supervisor starts a file remotely', async () => {
    const { sim, session, ctx } = setup({ role: 'supervisor' });
    session.start();
    await until(() => ctx.snapshot.getState().link === 'online');
    await ctx.commands.run(session.runFile, { path: '/jobs/coaster.gcode' });
    await until(() => session.detail.getState().machine.state === 'running');
    expect(sim.job?.startedBy).toBe('api');
    await advance(POLL_BUSY_MS + 200);
    expect(session.detail.getState().machine.startedBy).toBe('api');
  });

  it('turning safety off is dangerous and explains the risk; turning it on is not', () => {
    const { session } = setup();
    for (const off of [
      session.limitStopOff,
      session.tiltStopOff,
      session.movingStopOff,
      session.flameAlarmOff,
    ]) {
      expect(off.hazard).toBe('dangerous');
      expect(off.role).toBe('supervisor');
      expect(confirmationText(off, undefined)).toMatch(/OFF\?/);
    }
    for (const on of [session.limitStopOn, session.tiltStopOn, session.movingStopOn]) {
      expect(on.hazard).toBe('adjust');
      expect(confirmationText(on, undefined)).toBeNull();
    }
    expect(session.upgrade.confirmTwice).toBe(true);
    expect(confirmationText(session.upgrade, { file: new Blob(['x']), name: 'fw.bin' })).toMatch(/firmware/);
    expect(Object.keys(session.commands).every((id) => id.startsWith('xtool.'))).toBe(true);
  });

  it('G-code console: one line by GET, several by POST, with history', async () => {
    const { sim, session, ctx } = setup();
    session.start();
    await until(() => ctx.snapshot.getState().link === 'online');
    await ctx.commands.run(session.gcode, { code: 'M28' });
    await ctx.commands.run(session.gcode, { code: 'G0 X10\nG0 Y10\n' });
    expect(sim.gcode).toEqual(['M28', 'G0 X10', 'G0 Y10']);
    expect(session.detail.getState().console.map((c) => c.code)).toEqual(['M28', 'G0 X10\nG0 Y10']);
  });
});

describe('other xTool models', () => {
  it('shows "unsupported model" with what the device answered', async () => {
    const id = `laser-${++seq}`;
    // An F1/P2 answers unknown paths with {"result":"invalid request"} and has /status.
    const other: Simulator = {
      kind: 'xtool',
      fetch: async (_req, path) =>
        path.startsWith('/status')
          ? jsonResponse({ mode: 'P_IDLE', subMode: '', des: 'normal' })
          : jsonResponse({ result: 'invalid request' }),
      dispose: () => undefined,
    };
    server.use(...simulatorHandlers(id, other));
    const ctx = createContext(
      { id, name: 'F1', kind: 'xtool', simulated: true },
      { visibility: alwaysVisible },
    );
    session = new XtoolSession(ctx);
    session.start();
    await until(() => session?.detail.getState().model.family === 'unsupported');
    const snap = ctx.snapshot.getState();
    expect(snap.link).toBe('protocol-error');
    expect(snap.problem?.message).toMatch(/Unsupported model/);
    const answered = session.detail.getState().model.answered.join('\n');
    expect(answered).toMatch(/invalid request/);
    expect(answered).toMatch(/P_IDLE/);
    // It is asked again now and then (RECHECK_*), not every poll: the verdict is not final.
    const polls = session.poller.started;
    await advance(POLL_IDLE_MS);
    expect(session.poller.started).toBe(polls);
    await advance(RECHECK_MAX_MS * 3);
    expect(session.poller.started).toBeGreaterThan(polls);
    expect(session.poller.started - polls).toBeLessThanOrEqual(6);
    expect(ctx.snapshot.getState().link).toBe('protocol-error');
  });
});
