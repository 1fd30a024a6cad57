import type { SimControl, SimOptions, SimSocket, SimSocketHandler } from '../../../fleet/sim';
import { splitPath } from '../../../fleet/sim';
import { DEMO_FRAME, DEVICE, demoJob } from './data/device';

/**
 * The simulated xTool D1 Pro's state, time, physical world (its button, a flame, a bump: see
 * `controls()`) and its :8081 socket; simulator.ts adds the :8080 HTTP surface.
 */

export type SimMode = 'idle' | 'framing' | 'frame-ready' | 'job-loaded' | 'running' | 'paused' | 'stopping';

export interface SimJob {
  path: string;
  lines: number;
  /** Fractional line counter. */
  line: number;
  elapsedMs: number;
  startedBy: 'api' | 'button';
  /** Started from a file uploaded by software (WORKING_ONLINE) or from the SD card by the button. */
  online: boolean;
}

/** G-code lines of /cmd the simulator keeps (`gcode`, the newest). */
export const GCODE_KEPT = 500;
/** Frame terminator: the real firmware ends each frame with one extra character. */
export const FRAME_TERMINATOR = '\n';
/** Lines per second of a simulated job. */
export const LINES_PER_SECOND = 20;
export const STOP_MS = 1000;
export const FRAMING_MS = 4000;
/** The demo job (`demo` control): 4800 lines at LINES_PER_SECOND, four minutes of engraving. */
export const DEMO_JOB_LINES = 4800;
/** Demo: the operator walks to the machine and presses its button this long after the job is loaded. */
export const DEMO_PRESS_MS = 3000;
/** Demo: the next job is loaded this long after the last one finished (the piece is swapped). */
export const DEMO_REST_MS = 10_000;

export abstract class XtoolSimMachine {
  mode: SimMode = 'idle';
  /** Current job, or the last one (/progress keeps reporting it when idle). */
  job: SimJob | null = null;
  readonly files = new Map<string, string>();
  readonly dirs = new Set<string>(['/']);
  periphery: Record<keyof typeof DEVICE.periphery, number | string> = { ...DEVICE.periphery };
  name: string = DEVICE.name;
  sdCard = true;
  /** Fault: uploads answer "ok" but store nothing. */
  uploadLies = false;
  /** The last `GCODE_KEPT` G-code lines received over /cmd, for tests and the log. */
  readonly gcode: string[] = [];
  protected readonly sockets = new Set<SimSocket>();
  protected readonly now: () => number;
  private last: number;
  protected stopAt = 0;
  protected framingUntil = 0;
  /**
   * The `demo` control's loop: load a job, press the button, and when the job finishes load the
   * next one. Null when no demo runs. Only the simulator's own state changes; nothing is sent.
   */
  protected demo: { pressAt: number | null; loadAt: number | null } | null = null;
  private readonly timer: ReturnType<typeof setInterval>;

  constructor(readonly opts: SimOptions) {
    this.now = opts.now ?? Date.now;
    this.last = this.now();
    this.files.set('/frame.gcode', DEMO_FRAME);
    this.files.set('/tmp.gcode', demoJob());
    this.dirs.add('/jobs');
    this.files.set('/jobs/coaster.gcode', demoJob(300));
    this.timer = setInterval(() => this.tick(), opts.tickMs ?? 250);
  }

  dispose(): void {
    clearInterval(this.timer);
    for (const s of [...this.sockets]) s.close(1001, 'simulator disposed');
    this.sockets.clear();
  }

  // --- time ---------------------------------------------------------------------------------

  tick(): void {
    const t = this.now();
    const dt = Math.max(0, t - this.last);
    this.last = t;
    const job = this.job;
    if (this.mode === 'running' && job) {
      job.elapsedMs += dt;
      job.line = Math.min(job.lines, job.line + (dt * LINES_PER_SECOND) / 1000);
      if (job.line >= job.lines) {
        this.enter('idle', 'ok:IDLE');
        if (this.demo) this.demo = { pressAt: null, loadAt: t + DEMO_REST_MS };
      }
    } else if (this.mode === 'paused' && job) {
      job.elapsedMs += dt;
    } else if (this.mode === 'stopping' && t >= this.stopAt) {
      this.enter('idle', 'ok:IDLE');
    } else if (this.mode === 'framing' && t >= this.framingUntil) {
      this.enter('frame-ready', 'ok:WORKING_FRAME_READY');
    }
    this.demoStep(t);
  }

  /** One step of the demo loop, from tick(). */
  private demoStep(t: number): void {
    const d = this.demo;
    if (!d) return;
    if (d.loadAt !== null && t >= d.loadAt) {
      d.loadAt = null;
      // Someone else loaded or started something meanwhile: leave the machine to them.
      if (this.mode !== 'idle') return void (this.demo = null);
      this.loadDemoJob(DEMO_JOB_LINES);
      d.pressAt = t + DEMO_PRESS_MS;
    } else if (d.pressAt !== null && t >= d.pressAt) {
      d.pressAt = null;
      if (this.mode !== 'job-loaded') return void (this.demo = null);
      this.pressButton();
    }
  }

  /**
   * The `demo` control: the machine looks busy as a real one in use would. The vendor app loads a
   * job (ok:WORKING_ONLINE_READY), the operator presses the button a moment later, the job runs
   * for a few minutes, and after a short rest the next piece starts. Decision: a job that ends any
   * other way than finishing (stopped from the console or the button, a sensor alarm, ok:ERROR)
   * ends the demo: a real operator does not start the next piece after a stop or a flame.
   */
  startDemo(): void {
    if (this.busy || this.mode === 'job-loaded' || this.mode === 'frame-ready') {
      // Already busy: keep it going when the current job finishes.
      this.demo = { pressAt: this.mode === 'job-loaded' ? this.now() + DEMO_PRESS_MS : null, loadAt: null };
      return;
    }
    this.demo = { pressAt: null, loadAt: this.now() };
    this.demoStep(this.now());
  }

  /** Whether the demo loop runs (for tests and the control's label). */
  get demoRunning(): boolean {
    return this.demo !== null;
  }

  protected enter(mode: SimMode, frame: string | null): void {
    this.mode = mode;
    if (frame) this.broadcast(frame);
  }

  broadcast(frame: string): void {
    for (const s of this.sockets) s.send(frame + FRAME_TERMINATOR);
  }

  protected get busy(): boolean {
    return (
      this.mode === 'running' || this.mode === 'paused' || this.mode === 'stopping' || this.mode === 'framing'
    );
  }

  protected startJob(path: string, startedBy: 'api' | 'button', online: boolean): void {
    const text = this.files.get(path) ?? '';
    const lines = text.split('\n').filter((l) => l.trim() !== '' && !l.trim().startsWith(';')).length;
    this.job = { path, lines: Math.max(1, lines), line: 0, elapsedMs: 0, startedBy, online };
    this.enter('running', online ? 'ok:WORKING_ONLINE' : 'ok:WORKING_OFFLINE');
  }

  protected beginStop(frame: string): void {
    this.demo = null;
    this.stopAt = this.now() + STOP_MS;
    this.enter('stopping', frame);
  }

  // --- the physical world ---------------------------------------------------------------------

  /** A short press of the machine's button. */
  pressButton(): void {
    switch (this.mode) {
      case 'job-loaded':
        return this.startJob('/tmp.gcode', 'button', true);
      case 'frame-ready':
        this.framingUntil = this.now() + FRAMING_MS;
        return this.enter('framing', 'ok:WORKING_FRAMING');
      case 'running':
        return this.enter('paused', 'ok:PAUSING');
      case 'paused':
        return this.enter('running', this.job?.online ? 'ok:WORKING_ONLINE' : 'ok:WORKING_OFFLINE');
      case 'idle':
        // The button on an idle machine runs the file on the card (offline mode).
        if (this.sdCard && this.files.has('/tmp.gcode')) this.startJob('/tmp.gcode', 'button', false);
        return;
      default:
        return;
    }
  }

  /** Holding the button for 3 s cancels whatever is loaded or running. */
  holdButton(): void {
    if (this.mode === 'idle' || this.mode === 'stopping') return;
    // xTool's own code spells the stop frame WORK_STOPED.
    this.beginStop('WORK_STOPED');
  }

  /** A sensor trips: only when it is switched on. The job is aborted. Returns whether it fired. */
  trip(sensor: 'tilt' | 'moving' | 'limit' | 'flame'): boolean {
    const p = this.periphery;
    const on =
      sensor === 'flame'
        ? Number(p.flameAlarmSensitivity) !== 3
        : sensor === 'tilt'
          ? Number(p.tiltStopFlag) === 1
          : sensor === 'moving'
            ? Number(p.movingStopFlag) === 1
            : Number(p.limitStopFlag) === 1;
    if (!on) return false;
    this.demo = null;
    // The document: the sensor frame; the job is aborted and the machine is idle again.
    this.mode = 'idle';
    this.broadcast(`err:${sensor}Check`);
    return true;
  }

  /** Load a job as the vendor software would: upload /tmp.gcode, wait for the button. */
  loadDemoJob(lines?: number): void {
    if (this.busy) return;
    this.files.set('/tmp.gcode', demoJob(lines));
    this.enter('job-loaded', 'ok:WORKING_ONLINE_READY');
  }

  controls(): SimControl[] {
    return [
      {
        id: 'demo',
        label: 'Start a demo job',
        run: () => this.startDemo(),
      },
      { id: 'load-job', label: 'Load a demo job (as the vendor app would)', run: () => this.loadDemoJob() },
      { id: 'button', label: 'Press the button on the machine', run: () => this.pressButton() },
      { id: 'hold-button', label: 'Hold the button 3 s (cancel)', run: () => this.holdButton() },
      { id: 'flame', label: 'Flame under the laser', run: () => void this.trip('flame') },
      { id: 'tilt', label: 'Tilt the machine', run: () => void this.trip('tilt') },
      { id: 'moving', label: 'Bump the machine', run: () => void this.trip('moving') },
      { id: 'limit', label: 'Hit a limit switch', run: () => void this.trip('limit') },
      {
        id: 'error',
        label: 'Generic controller error',
        run: () => {
          this.mode = 'idle';
          this.demo = null;
          this.broadcast('ok:ERROR');
        },
      },
      {
        id: 'upload-fault',
        label: this.uploadLies ? 'Uploads work again' : 'Uploads fail but answer "ok"',
        run: () => (this.uploadLies = !this.uploadLies),
      },
      {
        id: 'sd-card',
        label: this.sdCard ? 'Remove the SD card' : 'Insert the SD card',
        run: () => (this.sdCard = !this.sdCard),
      },
    ];
  }

  // --- WebSocket on :8081 ------------------------------------------------------------------------

  socket(path: string, sock: SimSocket): SimSocketHandler | null {
    const { pathname } = splitPath(path);
    if (pathname !== '/' && pathname !== '') return null;
    // No snapshot on connect: the laser only pushes changes.
    this.sockets.add(sock);
    return {
      message: () => undefined, // read-only channel: the firmware ignores what clients send
      close: () => this.sockets.delete(sock),
    };
  }
}
