import { afterEach, beforeEach, describe, expect, it, vi } from 'vitest';
import type { SimSocket } from '../../../fleet/sim';
import {
  DEMO_JOB_LINES,
  DEMO_PRESS_MS,
  DEMO_REST_MS,
  FRAMING_MS,
  GCODE_KEPT,
  LINES_PER_SECOND,
  STOP_MS,
  XtoolSimulator,
} from './simulator';

let sim: XtoolSimulator;
beforeEach(() => {
  vi.useFakeTimers();
  sim = new XtoolSimulator({ id: 's', name: 'S' });
});
afterEach(() => {
  sim.dispose();
  vi.useRealTimers();
});

const get = async (path: string) => {
  const r = await sim.fetch(new Request(`http://x${path}`), path);
  return {
    status: r.status,
    type: r.headers.get('content-type'),
    body: (await r.json()) as Record<string, unknown>,
  };
};

function listen(): string[] {
  const frames: string[] = [];
  const sock: SimSocket = { send: (d) => frames.push(d), close: () => undefined };
  expect(sim.socket('/', sock)).not.toBeNull();
  return frames;
}

describe('XtoolSimulator', () => {
  it('answers with the quirks of the real firmware', async () => {
    const p = await get('/progress');
    expect(p.body).toEqual({ progress: '0', working: '0', line: '0' });
    expect(p.type ?? '').not.toMatch(/json/);
    expect((await get('/nothing/here')).body).toEqual({ result: 'no file' });
    expect(await get('/cnc/data?action=pause')).toMatchObject({ status: 200, body: { result: 'fail' } });
    expect((await get('/system?action=get_working_sta')).body).toEqual({ result: 'ok', working: '0' });
    expect((await get('/system?action=setTiltCheckThreshold&tiltCheckThreshold=300')).body.result).toBe(
      'fail',
    );
  });

  it('keeps only the newest /cmd lines, however many come (it runs as long as the gateway)', async () => {
    const cmd = (body: string) => sim.fetch(new Request('http://x/cmd', { method: 'POST', body }), '/cmd');
    for (let i = 0; i < GCODE_KEPT * 3; i++) await cmd(`G0 X${i}`);
    expect(sim.gcode).toHaveLength(GCODE_KEPT);
    expect(sim.gcode.at(-1)).toBe(`G0 X${GCODE_KEPT * 3 - 1}`);
    await cmd(Array.from({ length: GCODE_KEPT * 4 }, (_, i) => `G1 Y${i}`).join('\n'));
    expect(sim.gcode).toHaveLength(GCODE_KEPT);
    expect(sim.gcode[0]).toBe(`G1 Y${GCODE_KEPT * 3}`);
    expect(sim.gcode.at(-1)).toBe(`G1 Y${GCODE_KEPT * 4 - 1}`);
  });

  it('sends nothing on connect, terminated frames after', () => {
    const frames = listen();
    expect(frames).toEqual([]);
    sim.loadDemoJob();
    expect(frames).toEqual(['ok:WORKING_ONLINE_READY\n']);
  });

  it('runs a job through its lines over time and finishes', async () => {
    const frames = listen();
    sim.loadDemoJob();
    expect((await get('/system?action=get_working_sta')).body.working).toBe('2');
    sim.pressButton();
    vi.advanceTimersByTime(5000);
    const p = await get('/progress');
    expect(p.body.line).toBeGreaterThanOrEqual(5 * LINES_PER_SECOND - 5);
    expect(p.body.working).toBeGreaterThanOrEqual(4900);
    vi.advanceTimersByTime(60_000);
    expect(sim.mode).toBe('idle');
    expect(frames.at(-1)).toBe('ok:IDLE\n');
    expect((await get('/progress')).body.progress).toBe(100);
  });

  it('frames, stops with the misspelled frame from the button, the right one from the API', async () => {
    const frames = listen();
    sim.files.set('/frame.gcode', 'G1 X1\n');
    sim.pressButton(); // idle: runs /tmp.gcode offline
    expect(frames.at(-1)).toBe('ok:WORKING_OFFLINE\n');
    sim.holdButton();
    expect(frames.at(-1)).toBe('WORK_STOPED\n');
    vi.advanceTimersByTime(STOP_MS + 300);
    expect(sim.mode).toBe('idle');
    await get('/read?file=/jobs/coaster.gcode');
    expect(sim.mode).toBe('running');
    expect((await get('/cnc/data?action=stop')).body.result).toBe('ok');
    expect(frames.at(-1)).toBe('WORK_STOPPED\n');
    vi.advanceTimersByTime(STOP_MS + 300);
    const form = new FormData();
    form.append('file', new Blob(['G1 X2\n']), 'frame.gcode');
    await sim.fetch(
      new Request('http://x/upload?filetype=0', { method: 'POST', body: form }),
      '/upload?filetype=0',
    );
    expect(sim.mode).toBe('frame-ready');
    sim.pressButton();
    expect(frames.at(-1)).toBe('ok:WORKING_FRAMING\n');
    vi.advanceTimersByTime(FRAMING_MS + 300);
    expect(frames.at(-1)).toBe('ok:WORKING_FRAME_READY\n');
  });

  it('uploads answer ok even when they fail', async () => {
    sim.uploadLies = true;
    const form = new FormData();
    form.append('file', new Blob(['G1\n']), 'a.gcode');
    const r = await sim.fetch(
      new Request('http://x/upload?filename=/a.gcode', { method: 'POST', body: form }),
      '/upload?filename=/a.gcode',
    );
    expect(await r.json()).toEqual({ result: 'ok' });
    expect(sim.files.has('/a.gcode')).toBe(false);
    expect((await get('/list')).body.name).not.toContain('/a.gcode');
  });

  it('sensors trip only when switched on', async () => {
    const frames = listen();
    expect(sim.trip('flame')).toBe(true);
    expect(frames.at(-1)).toBe('err:flameCheck\n');
    await get('/system?action=setFlameAlarmSensitivity&flameAlarmSensitivity=3');
    expect(sim.trip('flame')).toBe(false);
    expect((await get('/peripherystatus')).body.flameAlarmSensitivity).toBe(3);
  });

  it('lists, deletes, refuses what it cannot do', async () => {
    expect((await get('/list')).body).toEqual({ type: 'dir', name: ['/frame.gcode', '/jobs', '/tmp.gcode'] });
    expect((await get('/list?dir=/jobs')).body.name).toEqual(['/jobs/coaster.gcode']);
    expect((await get('/delete?file=/jobs')).body.result).toBe('fail');
    expect((await get('/delete?file=/jobs/coaster.gcode')).body.result).toBe('ok');
    expect((await get('/delete?file=/jobs')).body.result).toBe('ok');
    expect((await get('/read?file=/nope.gcode')).body.result).toBe('fail');
  });
});

describe('the demo control', () => {
  const control = (id: string) => {
    const c = sim.controls().find((x) => x.id === id);
    if (!c) throw new Error(`no control ${id}`);
    return c;
  };

  it('loads a job, presses the button, runs for minutes and starts again', async () => {
    const frames = listen();
    expect(control('demo').label).toBe('Start a demo job');
    control('demo').run();
    // The vendor app loaded the job: the laser waits for the button ("2" = loaded, waiting).
    expect(frames).toEqual(['ok:WORKING_ONLINE_READY\n']);
    expect(sim.mode).toBe('job-loaded');
    expect((await get('/system?action=get_working_sta')).body.working).toBe('2');
    vi.advanceTimersByTime(DEMO_PRESS_MS + 300);
    // The operator pressed the button: an uploaded job started by the button.
    expect(frames.at(-1)).toBe('ok:WORKING_ONLINE\n');
    expect(sim.mode).toBe('running');
    expect((await get('/system?action=get_working_sta')).body.working).toBe('2');
    vi.advanceTimersByTime(120_000);
    const half = await get('/progress');
    expect(sim.mode).toBe('running');
    expect(Number(half.body.progress)).toBeGreaterThan(30);
    expect(Number(half.body.progress)).toBeLessThan(70);
    expect(Number(half.body.working)).toBeGreaterThanOrEqual(120_000);
    // Finishes after DEMO_JOB_LINES lines, rests, and the next piece starts.
    vi.advanceTimersByTime((DEMO_JOB_LINES / LINES_PER_SECOND) * 1000 - 120_000 + 500);
    expect(sim.mode).toBe('idle');
    expect(frames.at(-1)).toBe('ok:IDLE\n');
    vi.advanceTimersByTime(DEMO_REST_MS + DEMO_PRESS_MS + 600);
    expect(sim.mode).toBe('running');
    expect(frames.slice(-3)).toEqual(['ok:IDLE\n', 'ok:WORKING_ONLINE_READY\n', 'ok:WORKING_ONLINE\n']);
    expect(Number((await get('/progress')).body.progress)).toBeLessThan(5);
    // Only the simulator's own state: nothing was sent as G-code.
    expect(sim.gcode).toEqual([]);
  });

  it('ends when the job is stopped or a sensor trips, not just when it finishes', async () => {
    control('demo').run();
    vi.advanceTimersByTime(DEMO_PRESS_MS + 1000);
    expect(sim.mode).toBe('running');
    expect((await get('/cnc/data?action=stop')).body.result).toBe('ok');
    vi.advanceTimersByTime(STOP_MS + DEMO_REST_MS + DEMO_PRESS_MS + 1000);
    expect(sim.mode).toBe('idle');
    expect(sim.demoRunning).toBe(false);

    control('demo').run();
    vi.advanceTimersByTime(DEMO_PRESS_MS + 1000);
    expect(sim.trip('flame')).toBe(true);
    vi.advanceTimersByTime(DEMO_REST_MS + DEMO_PRESS_MS + 1000);
    expect(sim.mode).toBe('idle');
    expect(sim.demoRunning).toBe(false);
  });

  it('keeps a job that is already running and continues after it', () => {
    sim.loadDemoJob(100);
    sim.pressButton();
    control('demo').run();
    expect(sim.mode).toBe('running');
    vi.advanceTimersByTime(6000);
    expect(sim.mode).toBe('idle');
    vi.advanceTimersByTime(DEMO_REST_MS + DEMO_PRESS_MS + 600);
    expect(sim.mode).toBe('running');
    expect(sim.job?.lines).toBeGreaterThan(1000);
  });
});
