import {
  jsonResponse,
  splitPath,
  textResponse,
  type SimControl,
  type SimOptions,
  type SimSocket,
  type SimSocketHandler,
  type Simulator,
} from '../../../fleet/sim';
import { DEMO_FRAME, DEVICE, demoJob } from './data/device';

/**
 * A simulated xTool D1 Pro, faithful to ../shared/protocols/xtool-d-series-api.txt and the
 * fixtures: HTTP answers carry no JSON content type, numbers come as strings until the first job
 * ran, failures are {"result":"fail"} with HTTP 200, unknown paths {"result":"no file"}, uploads
 * answer "ok" even when they failed, WebSocket frames end with a terminator, the button stop frame
 * is misspelled WORK_STOPED, and the socket sends nothing on connect.
 *
 * The physical world (the machine's button, a flame, a bump) is in `controls()`.
 */

export type SimMode = 'idle' | 'framing' | 'frame-ready' | 'job-loaded' | 'running' | 'paused' | 'stopping';

interface SimJob {
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

const JSON_NO_TYPE = null;
const ok = () => jsonResponse({ result: 'ok' }, 200, JSON_NO_TYPE);
const fail = () => jsonResponse({ result: 'fail' }, 200, JSON_NO_TYPE);
const noFile = () => jsonResponse({ result: 'no file' }, 200, JSON_NO_TYPE);
const answer = (body: unknown) => jsonResponse(body, 200, JSON_NO_TYPE);

export class XtoolSimulator implements Simulator {
  readonly kind = 'xtool' as const;
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
  private readonly sockets = new Set<SimSocket>();
  private readonly now: () => number;
  private last: number;
  private stopAt = 0;
  private framingUntil = 0;
  /**
   * The `demo` control's loop: load a job, press the button, and when the job finishes load the
   * next one. Null when no demo runs. Only the simulator's own state changes; nothing is sent.
   */
  private demo: { pressAt: number | null; loadAt: number | null } | null = null;
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

  private enter(mode: SimMode, frame: string | null): void {
    this.mode = mode;
    if (frame) this.broadcast(frame);
  }

  broadcast(frame: string): void {
    for (const s of this.sockets) s.send(frame + FRAME_TERMINATOR);
  }

  private get busy(): boolean {
    return (
      this.mode === 'running' || this.mode === 'paused' || this.mode === 'stopping' || this.mode === 'framing'
    );
  }

  private startJob(path: string, startedBy: 'api' | 'button', online: boolean): void {
    const text = this.files.get(path) ?? '';
    const lines = text.split('\n').filter((l) => l.trim() !== '' && !l.trim().startsWith(';')).length;
    this.job = { path, lines: Math.max(1, lines), line: 0, elapsedMs: 0, startedBy, online };
    this.enter('running', online ? 'ok:WORKING_ONLINE' : 'ok:WORKING_OFFLINE');
  }

  private beginStop(frame: string): void {
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

  // --- HTTP on :8080 -----------------------------------------------------------------------------

  async fetch(req: Request, path: string): Promise<Response> {
    this.tick();
    const { pathname, query } = splitPath(path);
    const method = req.method.toUpperCase();
    const p = pathname.length > 1 ? pathname.replace(/\/+$/, '') : pathname;
    if (method === 'GET') {
      switch (p) {
        case '/ping':
          return ok();
        case '/progress':
          return answer(this.progressBody());
        case '/getmachinetype':
          return answer({ result: 'ok', type: DEVICE.machineType });
        case '/getlaserpowertype':
          return answer({ result: 'ok', power: DEVICE.laserPower });
        case '/getlaserpowerinfo':
          return answer({ result: 'ok', type: DEVICE.laserPowerInfoType, power: DEVICE.laserPower });
        case '/peripherystatus':
          return answer({ result: 'ok', ...this.periphery, sdCard: this.sdCard ? 1 : 0 });
        case '/system':
          return this.system(query);
        case '/cmd':
          return this.cmd(query.get('cmd'));
        case '/read':
          return this.read(query.get('file'));
        case '/list':
          return this.list(query.get('dir') ?? '/');
        case '/delete':
          return this.delete(query.get('file'));
        case '/cnc/data':
          return this.jobAction(query.get('action'));
        case '/framing':
          // "Usage unknown" (document): answer ok and do nothing.
          return ok();
        case '/updater':
          return textResponse(
            '<html><body><h1>xTool updater (simulated)</h1><form method="POST" action="/upgrade" enctype="multipart/form-data"><input type="file" name="file"><input type="submit"></form></body></html>',
            200,
            'text/html',
          );
        default:
          return noFile();
      }
    }
    if (method === 'POST') {
      switch (p) {
        case '/cmd':
          return this.cmd(await req.text());
        case '/upload':
        case '/cnc/data':
          return this.upload(req, query);
        case '/upgrade':
          return this.upgrade(req);
        case '/net':
          return query.get('action') === 'connsta' ? ok() : fail();
        default:
          return noFile();
      }
    }
    return noFile();
  }

  private progressBody(): Record<string, number | string> {
    const j = this.job;
    // Until a job ran since power-up the firmware sends strings (fixture quirk "progress":"0").
    if (!j) return { progress: '0', working: '0', line: '0' };
    return {
      progress: Math.round((j.line / j.lines) * 10000) / 100,
      working: Math.round(j.elapsedMs),
      line: Math.floor(j.line),
    };
  }

  private workingSta(): string {
    switch (this.mode) {
      case 'idle':
        return '0';
      case 'running':
      case 'paused':
      case 'stopping':
        return this.job?.startedBy === 'api' ? '1' : '2';
      default:
        // framing, frame ready, job loaded: "2" — file loaded, waiting for the button.
        return '2';
    }
  }

  private system(query: URLSearchParams): Response {
    const action = query.get('action');
    const setNumber = (key: keyof typeof DEVICE.periphery, param: string, min: number, max: number) => {
      const raw = query.get(param);
      const n = raw === null || raw.trim() === '' ? NaN : Number(raw);
      if (!Number.isInteger(n) || n < min || n > max) return fail();
      this.periphery[key] = n;
      return ok();
    };
    switch (action) {
      case 'mac':
        return answer({ result: 'ok', mac: DEVICE.mac });
      case 'version':
        return answer({ result: 'ok', sn: DEVICE.sn, version: DEVICE.version });
      case 'get_working_sta':
        return answer({ result: 'ok', working: this.workingSta() });
      case 'offset':
        return answer({ result: 'ok', x: DEVICE.offset.x, y: DEVICE.offset.y });
      case 'dotMode':
        return answer({ result: 'ok', dotMode: DEVICE.dotMode });
      case 'get_dev_name':
        return answer({ result: 'ok', name: this.name });
      case 'set_dev_name': {
        const name = query.get('name');
        if (!name || name.length > 32) return fail();
        this.name = name;
        return ok();
      }
      case 'setLimitStopSwitch':
        return setNumber('limitStopFlag', 'limitStopSwitch', 0, 1);
      case 'setTiltStopSwitch':
        return setNumber('tiltStopFlag', 'tiltStopSwitch', 0, 1);
      case 'setMovingStopSwitch':
        return setNumber('movingStopFlag', 'movingStopSwitch', 0, 1);
      case 'setTiltCheckThreshold':
        return setNumber('tiltThreshold', 'tiltCheckThreshold', 0, 255);
      case 'setMovingCheckThreshold':
        return setNumber('movingThreshold', 'movingCheckThreshold', 0, 255);
      case 'setFlameAlarmMode':
        // Supported values "unknown" (document): accept a byte.
        return setNumber('flameAlarmMode', 'flameAlarmMode', 0, 255);
      case 'setFlameAlarmSensitivity':
        return setNumber('flameAlarmSensitivity', 'flameAlarmSensitivity', 1, 3);
      default:
        return fail();
    }
  }

  private cmd(code: string | null): Response {
    const lines = (code ?? '')
      .split(/\r?\n/)
      .map((l) => l.trim())
      .filter((l) => l !== '');
    if (lines.length === 0) return fail();
    // Bounded: the demo fleet's laser runs in the gateway for as long as the server does.
    for (const l of lines.slice(-GCODE_KEPT)) this.gcode.push(l);
    if (this.gcode.length > GCODE_KEPT) this.gcode.splice(0, this.gcode.length - GCODE_KEPT);
    return ok();
  }

  private read(file: string | null): Response {
    if (!file || !this.sdCard || !this.files.has(file)) return fail();
    if (this.busy) return fail();
    const text = this.files.get(file) ?? '';
    // "If the file exists but cannot be executed machine will return ok while doing nothing."
    if (!/^\s*[GM]\d/m.test(text)) return ok();
    this.startJob(file, 'api', true);
    return ok();
  }

  private list(dir: string): Response {
    const d = dir.length > 1 ? dir.replace(/\/+$/, '') : dir;
    if (!this.sdCard || !this.dirs.has(d)) return fail();
    const prefix = d === '/' ? '/' : `${d}/`;
    const children = [...this.files.keys(), ...this.dirs].filter(
      (f) => f !== d && f.startsWith(prefix) && !f.slice(prefix.length).includes('/'),
    );
    return answer({ type: 'dir', name: children.sort() });
  }

  private delete(file: string | null): Response {
    if (!file || !this.sdCard) return fail();
    if (this.busy && this.job?.path === file) return fail();
    if (this.files.delete(file)) return ok();
    if (this.dirs.has(file) && file !== '/') {
      const empty = ![...this.files.keys(), ...this.dirs].some((f) => f.startsWith(`${file}/`));
      if (!empty) return fail();
      this.dirs.delete(file);
      return ok();
    }
    return fail();
  }

  private jobAction(action: string | null): Response {
    switch (action) {
      case 'pause':
        if (this.mode !== 'running') return fail();
        this.enter('paused', 'ok:PAUSING');
        return ok();
      case 'resume':
        if (this.mode !== 'paused') return fail();
        this.enter('running', this.job?.online ? 'ok:WORKING_ONLINE' : 'ok:WORKING_OFFLINE');
        return ok();
      case 'stop':
        if (this.mode === 'idle' || this.mode === 'stopping') return fail();
        this.beginStop('WORK_STOPPED');
        return ok();
      default:
        return fail();
    }
  }

  private async upload(req: Request, query: URLSearchParams): Promise<Response> {
    let file: File | null = null;
    try {
      const form = await req.formData();
      const f = form.get('file');
      if (f && typeof f !== 'string') file = f;
    } catch {
      file = null;
    }
    const explicit = query.get('filename');
    const filetype = query.get('filetype');
    const path = explicit ?? (filetype === '0' ? '/frame.gcode' : '/tmp.gcode');
    const parent = path.slice(0, path.lastIndexOf('/')) || '/';
    // The firmware answers "ok" whatever happened (document): every failure below is silent.
    if (!file || this.uploadLies || !this.sdCard || this.busy || !this.dirs.has(parent)) return ok();
    this.files.set(path, await file.text());
    if (path === '/tmp.gcode') this.enter('job-loaded', 'ok:WORKING_ONLINE_READY');
    else if (path === '/frame.gcode') this.enter('frame-ready', 'ok:WORKING_FRAME_READY');
    return ok();
  }

  private async upgrade(req: Request): Promise<Response> {
    try {
      const form = await req.formData();
      const f = form.get('file');
      const good = f !== null && typeof f !== 'string' && f.size > 0 && f.name.toLowerCase().endsWith('.bin');
      // The simulator never changes its firmware; it only answers as the updater does.
      return textResponse(good && !this.busy ? 'OK' : 'FAIL');
    } catch {
      return textResponse('FAIL');
    }
  }
}

export function createXtoolSimulator(opts: SimOptions): XtoolSimulator {
  return new XtoolSimulator(opts);
}
