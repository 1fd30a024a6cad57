import { describe, expect, it } from 'vitest';
import {
  INITIAL_STATE,
  alarmForFrame,
  applyFrame,
  applyJobAction,
  applyPoll,
  jobSummary,
  raiseAlarm,
  stateLabel,
  toActivity,
  type MachineState,
} from './state';
import { parseFrameText, type Progress, type WorkingCode } from './wire';

/** Feed raw frames (with terminators, as the laser sends them). */
function run(frames: string[], from: MachineState = INITIAL_STATE): MachineState {
  return frames.reduce((s, f) => applyFrame(s, parseFrameText(f)), from);
}

const prog = (progress: number, working: number): Progress => ({ progress, working, line: 0 });

describe('frames drive the state', () => {
  it('upload, button, pause, resume, finish', () => {
    const loaded = run(['ok:WORKING_ONLINE_READY\n']);
    expect(loaded.state).toBe('job-loaded');
    expect(stateLabel(loaded)).toMatch(/press the button on the machine/);
    expect(toActivity(loaded.state)).toBe('idle');
    const running = run(['ok:WORKING_ONLINE\n'], loaded);
    expect(toActivity(running.state)).toBe('running');
    // A loaded job only starts with the button: not "started remotely".
    expect(running.startedBy).toBe('button');
    expect(stateLabel(running)).toMatch(/button/);
    // From idle, WORKING_ONLINE is a remote start (/read).
    expect(run(['ok:IDLE\n', 'ok:WORKING_ONLINE\n']).startedBy).toBe('api');
    const paused = run(['ok:PAUSING\n'], running);
    expect(paused.state).toBe('paused');
    expect(toActivity(paused.state)).toBe('paused');
    expect(run(['ok:WORKING_ONLINE\n', 'ok:IDLE\n'], paused).state).toBe('idle');
  });

  it('a job started with the button says so', () => {
    const s = run(['ok:WORKING_OFFLINE\0']);
    expect(s).toMatchObject({ state: 'running', startedBy: 'button' });
    expect(stateLabel(s)).toMatch(/button/);
  });

  it('framing and frame ready', () => {
    const ready = run(['ok:WORKING_FRAME_READY\n']);
    expect(stateLabel(ready)).toMatch(/Frame loaded/);
    const framing = run(['ok:WORKING_FRAMING\n'], ready);
    expect(toActivity(framing.state)).toBe('running');
    expect(run(['ok:WORKING_FRAME_READY\n'], framing).state).toBe('frame-ready');
  });

  it('both stop spellings mean stopping, then idle', () => {
    for (const stop of ['WORK_STOPPED\n', 'WORK_STOPED\n']) {
      const s = run(['ok:WORKING_ONLINE\n', stop]);
      expect(s.state).toBe('stopping');
      expect(toActivity(s.state)).toBe('stopping');
      expect(run(['ok:IDLE\n'], s).state).toBe('idle');
    }
  });

  it('sensor frames are alarms, ok:ERROR an error; unknown frames change nothing', () => {
    const flame = run(['ok:WORKING_ONLINE\n', 'err:flameCheck\n']);
    expect(flame).toMatchObject({ state: 'alarm', sensor: 'flame' });
    expect(toActivity(flame.state)).toBe('alarm');
    expect(stateLabel(flame)).toMatch(/flame sensor/);
    expect(toActivity(run(['ok:ERROR\n']).state)).toBe('error');
    const running = run(['ok:WORKING_ONLINE\n']);
    expect(run(['ok:NEW_THING\n'], running)).toEqual(running);
  });
});

describe('alarms', () => {
  it('flame is critical and blocking; tilt, moving, limit warnings', () => {
    const flame = alarmForFrame(parseFrameText('err:flameCheck\n'), 5);
    expect(flame).toMatchObject({ id: 'xtool-flame', severity: 'critical', blocking: true, since: 5 });
    for (const s of ['tilt', 'moving', 'limit']) {
      const a = alarmForFrame(parseFrameText(`err:${s}Check\n`), 1);
      expect(a?.severity).toBe('warning');
      expect(a?.blocking).toBeFalsy();
    }
    expect(alarmForFrame(parseFrameText('ok:ERROR\n'), 1)?.severity).toBe('warning');
    expect(alarmForFrame(parseFrameText('ok:IDLE\n'), 1)).toBeNull();
  });

  it('a repeated condition keeps one alarm with its first time', () => {
    const a1 = alarmForFrame(parseFrameText('err:flameCheck'), 1)!;
    const a2 = alarmForFrame(parseFrameText('err:flameCheck'), 9)!;
    const list = raiseAlarm(raiseAlarm([], a1), a2);
    expect(list).toHaveLength(1);
    expect(list[0]?.since).toBe(1);
  });
});

describe('polls', () => {
  const poll = (s: MachineState, w: WorkingCode, p: Progress | null = null, prev: Progress | null = null) =>
    applyPoll(s, w, p, prev);

  it('idle ends everything, also a missed ok:IDLE and an alarm state', () => {
    expect(poll(run(['ok:WORKING_ONLINE\n']), 'idle').state).toBe('idle');
    expect(poll(run(['err:tiltCheck\n']), 'idle').state).toBe('idle');
  });

  it('busy keeps the sub-state a frame gave', () => {
    expect(poll(run(['ok:WORKING_ONLINE\n', 'ok:PAUSING\n']), 'api')).toMatchObject({
      state: 'paused',
      startedBy: 'api',
    });
    expect(poll(run(['ok:WORKING_ONLINE_READY\n']), 'button').state).toBe('job-loaded');
    // …until time moves: the button was pressed and the frame missed.
    const loaded = run(['ok:WORKING_ONLINE_READY\n']);
    expect(poll(loaded, 'button', prog(100, 56197), prog(100, 56197)).state).toBe('job-loaded');
    expect(poll(loaded, 'button', prog(1, 800), prog(100, 56197))).toMatchObject({
      state: 'running',
      startedBy: 'button',
    });
    expect(poll(run(['ok:WORKING_ONLINE\n']), 'button')).toMatchObject({
      state: 'running',
      startedBy: 'button',
    });
  });

  it('"1" with nothing known is a remotely started job', () => {
    expect(poll(INITIAL_STATE, 'api')).toMatchObject({ state: 'running', startedBy: 'api' });
  });

  it('"2" with nothing known: ambiguous, then progress decides', () => {
    const first = poll(INITIAL_STATE, 'button', prog(10, 1000), null);
    expect(first.state).toBe('button');
    expect(poll(first, 'button', prog(10, 1000), prog(10, 1000)).state).toBe('job-loaded');
    expect(poll(first, 'button', prog(12, 4000), prog(10, 1000))).toMatchObject({
      state: 'running',
      startedBy: 'button',
    });
  });

  it('a job action the laser accepted is its word for the new state; polls keep it', () => {
    const running = run(['ok:WORKING_OFFLINE\n']);
    const paused = applyJobAction(running, 'pause');
    expect(paused).toMatchObject({ state: 'paused', startedBy: 'button' });
    expect(poll(paused, 'button').state).toBe('paused');
    expect(applyJobAction(paused, 'resume').state).toBe('running');
    expect(poll(applyJobAction(paused, 'stop'), 'idle').state).toBe('idle');
  });

  it('an unknown working code keeps the state', () => {
    const s = run(['ok:PAUSING\n']);
    expect(poll(s, 'unknown')).toBe(s);
  });
});

describe('job summary', () => {
  it('progress as a fraction, elapsed in seconds, remaining estimated', () => {
    const j = jobSummary(run(['ok:WORKING_ONLINE\n']), prog(25, 60_000), 'coaster.gcode');
    expect(j).toEqual({ name: 'coaster.gcode', progress: 0.25, elapsed: 60, remaining: 180 });
  });
  it('no job when idle, no progress when only loaded', () => {
    expect(jobSummary(run(['ok:IDLE\n']), prog(100, 5000), null)).toBeNull();
    expect(jobSummary(run(['ok:WORKING_ONLINE_READY\n']), prog(100, 5000), 'a.gcode')).toEqual({
      name: 'a.gcode',
      progress: null,
      elapsed: null,
      remaining: null,
    });
  });
});
