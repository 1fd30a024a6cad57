import type { Activity, Alarm, JobSummary } from '../../fleet/types';
import type { Progress, Sensor, WorkingCode, XtoolFrame } from './wire';

/**
 * The laser's state machine, as pure functions: WebSocket frames and polls in, state out.
 * The session feeds it; tests drive it with frame sequences.
 */

export type XState =
  | 'unknown'
  | 'idle'
  | 'framing'
  | 'frame-ready'
  | 'job-loaded'
  | 'running'
  | 'paused'
  | 'stopping'
  /** get_working_sta "2" with nothing else known: running from the button, or loaded and waiting. */
  | 'button'
  /** A sensor stopped the job (err:*Check). */
  | 'alarm'
  /** ok:ERROR */
  | 'error';

export type StartedBy = 'api' | 'button' | null;

export interface MachineState {
  state: XState;
  startedBy: StartedBy;
  /** The sensor of the last err:*Check frame, while state is 'alarm'. */
  sensor: Sensor | null;
}

export const INITIAL_STATE: MachineState = { state: 'unknown', startedBy: null, sensor: null };

/** States in which the laser has a job (or frame) loaded or running: polled every 3 s. */
export function isBusy(s: XState): boolean {
  return (
    s === 'framing' ||
    s === 'frame-ready' ||
    s === 'job-loaded' ||
    s === 'running' ||
    s === 'paused' ||
    s === 'stopping' ||
    s === 'button'
  );
}

/** A job is moving or could move without the button: running, framing, or paused mid-job. */
export function isRunningJob(s: XState): boolean {
  return s === 'running' || s === 'framing' || s === 'paused' || s === 'stopping' || s === 'button';
}

/** Apply one WebSocket frame. Unknown frames change nothing (the session logs them). */
export function applyFrame(cur: MachineState, f: XtoolFrame): MachineState {
  switch (f.kind) {
    case 'state':
      switch (f.state) {
        case 'idle':
          return { state: 'idle', startedBy: null, sensor: null };
        case 'running-online':
          // Software-uploaded job: started by /read (api) or with the button after an upload.
          // A loaded job waits for the button (ok:WORKING_ONLINE_READY), so starting from there
          // is the button; otherwise keep what we knew, the next poll ("1" or "2") says which.
          return {
            state: 'running',
            startedBy: cur.state === 'job-loaded' ? 'button' : (cur.startedBy ?? 'api'),
            sensor: null,
          };
        case 'running-offline':
          return { state: 'running', startedBy: 'button', sensor: null };
        case 'job-loaded':
          return { state: 'job-loaded', startedBy: null, sensor: null };
        case 'framing':
          return { state: 'framing', startedBy: 'button', sensor: null };
        case 'frame-ready':
          return { state: 'frame-ready', startedBy: null, sensor: null };
        case 'paused':
          return { state: 'paused', startedBy: cur.startedBy, sensor: null };
      }
      return cur;
    case 'stopped':
      return { state: 'stopping', startedBy: cur.startedBy, sensor: null };
    case 'error':
      return { state: 'error', startedBy: null, sensor: null };
    case 'sensor':
      return { state: 'alarm', startedBy: null, sensor: f.sensor };
    case 'unknown':
      return cur;
  }
}

/**
 * The state after the laser answered "ok" to a job action: it answers "fail" when the action is
 * not possible in the current state (document), so "ok" is its own word that it paused, resumed
 * or is stopping. Frames and polls confirm it; without a socket it is the only way to see a pause.
 */
export function applyJobAction(cur: MachineState, action: 'pause' | 'resume' | 'stop'): MachineState {
  switch (action) {
    case 'pause':
      return { state: 'paused', startedBy: cur.startedBy, sensor: null };
    case 'resume':
      return { state: 'running', startedBy: cur.startedBy, sensor: null };
    case 'stop':
      return { state: 'stopping', startedBy: cur.startedBy, sensor: null };
  }
}

/**
 * Apply a poll of get_working_sta (+ /progress). The poll is the truth about "busy or not";
 * frames refine it: a poll that says "busy" keeps the busy sub-state a frame gave (paused,
 * job loaded, framing…), a poll that says idle ends everything (a missed ok:IDLE, a job that
 * ended after a sensor alarm). With "2" and nothing else known, progress decides: elapsed time
 * moving means running, else loaded and waiting for the button.
 */
export function applyPoll(
  cur: MachineState,
  working: WorkingCode,
  progress: Progress | null,
  previous: Progress | null,
): MachineState {
  if (working === 'idle') return { state: 'idle', startedBy: null, sensor: null };
  if (working === 'unknown') return cur;
  const by: StartedBy = working === 'api' ? 'api' : 'button';
  if (cur.state === 'running' || cur.state === 'paused' || cur.state === 'stopping') {
    return { state: cur.state, startedBy: by, sensor: null };
  }
  // Elapsed time ("time since the job was started", pauses included) changing between two polls
  // means a job runs; unchanged means it has not started (/progress still shows the last job).
  const moving = progress !== null && previous !== null && progress.working !== previous.working;
  if (working === 'button' && cur.state === 'job-loaded') {
    // The button was pressed and we missed the frame (or have no socket).
    return moving ? { state: 'running', startedBy: 'button', sensor: null } : cur;
  }
  if (working === 'button' && (cur.state === 'frame-ready' || cur.state === 'framing')) return cur;
  if (working === 'api') return { state: 'running', startedBy: 'api', sensor: null };
  // "2" without a frame to go by: running if time moves, else loaded and waiting for the button.
  if (progress && previous) {
    return moving
      ? { state: 'running', startedBy: 'button', sensor: null }
      : { state: 'job-loaded', startedBy: null, sensor: null };
  }
  return { state: 'button', startedBy: null, sensor: null };
}

export function toActivity(s: XState): Activity {
  switch (s) {
    case 'unknown':
      return 'unknown';
    // A loaded job or frame waits for a person at the machine: nothing moves, the fleet sees
    // "idle" with the label saying what is loaded (decision: the document has no such class).
    case 'idle':
    case 'frame-ready':
    case 'job-loaded':
      return 'idle';
    case 'framing':
    case 'running':
    case 'button':
      return 'running';
    case 'paused':
      return 'paused';
    case 'stopping':
      return 'stopping';
    case 'alarm':
      return 'alarm';
    case 'error':
      return 'error';
  }
}

const SENSOR_WORDS: Record<Sensor, string> = {
  tilt: 'tilt sensor',
  moving: 'movement sensor',
  limit: 'limit switch',
  flame: 'flame sensor',
};

export function stateLabel(m: MachineState): string {
  switch (m.state) {
    case 'unknown':
      return 'Connecting…';
    case 'idle':
      return 'Idle';
    case 'framing':
      return 'Framing (tracing the outline)';
    case 'frame-ready':
      return 'Frame loaded — press the button on the machine to trace it';
    case 'job-loaded':
      return 'Job loaded — press the button on the machine';
    case 'running':
      return m.startedBy === 'button'
        ? 'Running (started with the button on the machine)'
        : m.startedBy === 'api'
          ? 'Running (started remotely)'
          : 'Running';
    case 'button':
      return 'Busy: running a job started with the button, or waiting for the button';
    case 'paused':
      return 'Paused';
    case 'stopping':
      return 'Stopping';
    case 'alarm':
      return `Stopped by the ${m.sensor ? SENSOR_WORDS[m.sensor] : 'sensors'}`;
    case 'error':
      return 'Error reported by the laser';
  }
}

/** The snapshot alarm for a frame, or null. Ids are stable per condition. */
export function alarmForFrame(f: XtoolFrame, at: number): Alarm | null {
  if (f.kind === 'error') {
    return {
      id: 'xtool-error',
      severity: 'warning',
      message: 'The laser reported an error (ok:ERROR). Check the machine.',
      since: at,
      clears: 'acknowledge',
    };
  }
  if (f.kind !== 'sensor') return null;
  switch (f.sensor) {
    case 'flame':
      return {
        id: 'xtool-flame',
        severity: 'critical',
        blocking: true,
        message: 'FLAME DETECTED — the job was aborted. Go to the laser now and check for fire.',
        since: at,
        clears: 'acknowledge after checking the machine',
      };
    case 'tilt':
      return {
        id: 'xtool-tilt',
        severity: 'warning',
        message: 'Tilt sensor tripped — the job was aborted. Check that the laser stands level.',
        since: at,
        clears: 'acknowledge',
      };
    case 'moving':
      return {
        id: 'xtool-moving',
        severity: 'warning',
        message: 'Movement sensor tripped — the job was aborted. The laser was moved or bumped.',
        since: at,
        clears: 'acknowledge',
      };
    case 'limit':
      return {
        id: 'xtool-limit',
        severity: 'warning',
        message: 'Limit switch hit — the job was aborted. Check the work area and the origin.',
        since: at,
        clears: 'acknowledge',
      };
  }
}

/**
 * Add an alarm to the list: an alarm already present and not yet acknowledged keeps its `since`
 * (same condition, same alarm); otherwise it is added fresh.
 */
export function raiseAlarm(alarms: readonly Alarm[], a: Alarm): Alarm[] {
  const existing = alarms.find((x) => x.id === a.id);
  if (existing && !existing.acknowledged) return alarms.slice();
  return [...alarms.filter((x) => x.id !== a.id), a];
}

/** The job for the snapshot: null unless something is loaded or running. */
export function jobSummary(
  m: MachineState,
  progress: Progress | null,
  name: string | null,
): JobSummary | null {
  if (!isBusy(m.state)) return null;
  const loaded = m.state === 'job-loaded' || m.state === 'frame-ready';
  const frameName = m.state === 'framing' || m.state === 'frame-ready' ? 'frame.gcode (framing)' : null;
  if (loaded || !progress) return { name: frameName ?? name, progress: null, elapsed: null, remaining: null };
  const p = Math.min(1, Math.max(0, progress.progress / 100));
  const elapsed = progress.working / 1000;
  // Remaining time is estimated from the pace so far (the firmware does not report it).
  const remaining = p >= 0.01 && p < 1 ? Math.round((elapsed * (1 - p)) / p) : null;
  return { name: frameName ?? name, progress: p, elapsed, remaining };
}
