import { isObject, type JsonObject } from '../patch';
import { EMPTY_JOB_FILE } from './data/model';
import { iso, normalize } from './files';
import { arr, DuetSimLink, o, type DuetSimOptions } from './link';

/** The simulated printer on top of the model: heaters, jobs, message boxes, time and the demo. */

interface RunningJob {
  path: string;
  size: number;
  printTime: number;
  layers: number;
  layerHeight: number;
  simulate: boolean;
  /** seconds of printing done (excluding warm-up and pauses) */
  printed: number;
  warming: boolean;
}

export interface MessageBoxAnswer {
  seq: number;
  cancelled: boolean;
  value: string | null;
}

const AMBIENT = 21;

/** Value of a G-code parameter: `P"text"` (quotes removed, "" unescaped), `S12`, `R{...}`. */
export function gcodeParam(line: string, letter: string): string | null {
  const re = new RegExp(`\\s${letter}("(?:[^"]|"")*"|\\{[^}]*\\}|[^\\s;]*)`, 'i');
  const m = re.exec(` ${line.replace(/^\s*[GMT]\d+(?:\.\d+)?/i, '')}`);
  if (!m) return null;
  const v = m[1] ?? '';
  if (v.startsWith('"')) return v.slice(1, -1).replace(/""/g, '"');
  return v;
}

export abstract class DuetSimMachine extends DuetSimLink {
  /** The last 500 answers received with M292, for tests and the developer panel. */
  readonly answers: MessageBoxAnswer[] = [];
  /** Codes received, for tests. */
  readonly codes: string[] = [];
  private last: number;
  protected job: RunningJob | null = null;
  private boxSeq = 0;
  private boxOpenedAt = 0;
  private startingUntil = 0;
  protected phaseUntil = 0;
  /** Demo mode (control `demo`): the print to repeat, and when to start it next. */
  private demo: { path: string; nextAt: number } | null = null;

  constructor(opts: DuetSimOptions) {
    super(opts);
    this.last = this.now();
  }

  protected setHeater(i: number, temp: number): void {
    const h = this.heaters()[i];
    if (!h || Number.isNaN(temp)) return;
    h['active'] = temp;
    h['state'] = temp > 0 ? 'active' : 'off';
  }

  protected setFan(i: number, v: number): void {
    const f = arr(this.model['fans'])[i];
    if (!isObject(f)) return;
    f['requestedValue'] = v;
    f['actualValue'] = v;
  }

  protected heatersOff(): void {
    for (const h of this.heaters()) {
      if (!h) continue;
      h['active'] = 0;
      if (h['state'] !== 'fault') h['state'] = 'off';
    }
  }

  protected startJob(rawPath: string, simulate: boolean): string {
    const code = simulate ? 'M37' : 'M32';
    const path = normalize(rawPath.includes(':') ? rawPath : `0:/gcodes/${rawPath.replace(/^\/+/, '')}`);
    if (this.status !== 'idle')
      return `Error: ${code}: Cannot set file to print, because a file is already being printed`;
    const info = this.fs.fileInfo(path, true);
    if (!info) return `Error: ${code}: Could not find file ${path}`;
    const printTime = Number(info['printTime'] ?? 120) || 120;
    this.job = {
      path,
      size: Number(info['size']),
      printTime,
      layers: Number(info['numLayers']) || 1,
      layerHeight: Number(info['layerHeight']) || 0.2,
      simulate,
      printed: 0,
      warming: !simulate,
    };
    const job = this.jobObj;
    job['file'] = info;
    job['filePosition'] = 0;
    job['duration'] = 0;
    job['layer'] = 0;
    job['layerTime'] = 0;
    job['pauseDuration'] = 0;
    job['warmUpDuration'] = 0;
    job['timesLeft'] = { filament: null, file: null, slicer: printTime };
    for (const a of this.axes()) a['homed'] = true;
    if (!simulate) {
      this.setHeater(0, 60);
      this.setHeater(1, 210);
    }
    this.setStatus(simulate ? 'simulating' : 'processing');
    this.message(0, simulate ? `Simulating file ${path}` : `Started printing file ${path}`);
    return '';
  }

  private finishJob(how: 'done' | 'cancelled' | 'aborted'): void {
    const j = this.job;
    const job = this.jobObj;
    if (j) {
      const duration = Number(job['duration'] ?? 0);
      job['lastFileName'] = j.path;
      job['lastDuration'] = duration;
      job['lastFileCancelled'] = how === 'cancelled';
      job['lastFileAborted'] = how === 'aborted';
      job['lastFileSimulated'] = j.simulate;
      const hm = `${Math.floor(duration / 3600)}h ${Math.floor((duration % 3600) / 60)}m`;
      if (j.simulate && how === 'done') {
        const t = Math.round(j.printTime);
        this.message(
          0,
          `File ${j.path} will print in ${Math.floor(t / 3600)}h ${Math.floor((t % 3600) / 60)}m plus heating time`,
        );
      } else if (how === 'done') this.message(0, `Finished printing file ${j.path}, print time was ${hm}`);
      else if (how === 'cancelled')
        this.message(0, `Cancelled printing file ${j.path}, print time was ${hm}`);
    }
    this.job = null;
    // Demo mode repeats a finished print after a short pause; a cancel or an emergency stop is
    // someone taking over the machine, so the demo ends there.
    if (this.demo) {
      if (how === 'done') this.demo.nextAt = this.now() + DEMO_PAUSE_MS;
      else this.demo = null;
    }
    job['file'] = { ...EMPTY_JOB_FILE, thumbnails: [], filament: [] };
    job['filePosition'] = 0;
    job['duration'] = null;
    job['layer'] = null;
    job['layerTime'] = null;
    job['pauseDuration'] = null;
    job['warmUpDuration'] = null;
    job['timesLeft'] = { filament: null, file: null, slicer: null };
    this.heatersOff();
    this.setFan(0, 0);
    if (how !== 'aborted') this.setStatus('idle');
  }

  protected emergencyStop(): void {
    if (this.job) this.finishJob('aborted');
    this.heatersOff();
    for (const a of this.axes()) a['homed'] = false;
    this.state['messageBox'] = null;
    this.setStatus('halted');
  }

  protected reset(): void {
    if (this.job) this.finishJob('aborted');
    this.heatersOff();
    for (const a of this.axes()) a['homed'] = false;
    this.state['messageBox'] = null;
    this.state['upTime'] = 0;
    this.state['msUpTime'] = 0;
    this.setStatus('starting');
    this.startingUntil = this.now() + 1500;
  }

  // ------------------------------------------------------------------ message boxes

  /** Open a message box (M291) of a mode 0–7 with mode-appropriate defaults. */
  raiseMessageBox(
    mode: number,
    opts: Partial<{
      message: string;
      title: string;
      timeout: number;
      cancelButton: boolean;
      axisControls: number;
    }> = {},
  ): number {
    const seq = ++this.boxSeq;
    const box: JsonObject = {
      axisControls: opts.axisControls ?? 0,
      cancelButton: opts.cancelButton ?? mode === 3,
      choices: mode === 4 ? ['PLA', 'PETG', 'ABS'] : null,
      default: mode === 4 ? 0 : mode === 5 ? 3 : mode === 6 ? 0.2 : mode === 7 ? 'part-001' : null,
      max: mode === 5 ? 10 : mode === 6 ? 1 : mode === 7 ? 20 : null,
      message: opts.message ?? MODE_TEXT[mode] ?? 'Message',
      min: mode === 5 ? 1 : mode === 6 ? 0 : mode === 7 ? 1 : null,
      mode,
      seq,
      timeout: opts.timeout ?? 0,
      title: opts.title ?? `Simulated message box (mode ${mode})`,
    };
    this.state['messageBox'] = box;
    this.boxOpenedAt = this.now();
    this.flush();
    return seq;
  }

  protected answerBox(line: string): string {
    const box = this.state['messageBox'];
    if (!isObject(box)) return '';
    const s = gcodeParam(line, 'S');
    if (s !== null && Number(s) !== box['seq']) return ''; // a stale answer: RRF ignores it
    const cancelled = gcodeParam(line, 'P') === '1';
    const r = gcodeParam(line, 'R');
    let value: string | null = null;
    if (r !== null) {
      const inner = r.replace(/^\{|\}$/g, '');
      value = /^".*"$/.test(inner) ? inner.slice(1, -1).replace(/""/g, '"') : inner;
    }
    this.answers.push({ seq: Number(box['seq']), cancelled, value });
    if (this.answers.length > 500) this.answers.splice(0, this.answers.length - 500);
    this.state['messageBox'] = null;
    return '';
  }

  // ------------------------------------------------------------------ time

  tick(): void {
    const now = this.now();
    const dt = Math.max(0, Math.min(5000, now - this.last)) / 1000;
    this.last = now;
    const st = this.state;
    st['upTime'] = Math.round(Number(st['upTime'] ?? 0) + dt);
    st['time'] = iso(now);
    // Heaters approach their targets.
    this.heaters().forEach((h, i) => {
      if (!h) return;
      const target =
        h['state'] === 'active'
          ? Number(h['active'])
          : h['state'] === 'standby'
            ? Number(h['standby'])
            : AMBIENT;
      const tau = i === 0 ? 12 : i === 3 ? 40 : 5;
      const cur = Number(h['current']);
      h['current'] = Math.round((cur + (target - cur) * (1 - Math.exp(-dt / tau))) * 10) / 10;
    });
    const hotend = this.heaters()[1];
    if (hotend) this.setFan(1, Number(hotend['current']) > 45 ? 1 : 0);
    const sensors = arr(o(this.model['sensors'])['analog']);
    sensors.forEach((s, i) => {
      const h = this.heaters()[i];
      if (isObject(s) && h) s['lastReading'] = h['current'] ?? null;
    });
    // Phase changes.
    const status = this.status;
    if (status === 'starting' && now >= this.startingUntil) this.setStatus('idle');
    if (now >= this.phaseUntil) {
      if (status === 'pausing') this.setStatus('paused');
      else if (status === 'resuming') this.setStatus('processing');
      else if (status === 'cancelling') this.finishJob('cancelled');
    }
    this.advanceJob(dt);
    if (this.demo && !this.job && this.status === 'idle' && now >= this.demo.nextAt) this.startDemoJob();
    const box = st['messageBox'];
    if (
      isObject(box) &&
      Number(box['timeout']) > 0 &&
      now - this.boxOpenedAt >= Number(box['timeout']) * 1000
    )
      st['messageBox'] = null;
    for (const [k, s] of this.sessions)
      if (s.sockets === 0 && now - s.lastSeen > this.sessionTimeoutMs) this.sessions.delete(k);
    this.flush();
  }

  private advanceJob(dt: number): void {
    const j = this.job;
    if (!j) return;
    const job = this.jobObj;
    const status = this.status;
    if (status === 'paused') {
      job['pauseDuration'] = Number(job['pauseDuration'] ?? 0) + dt;
      return;
    }
    if (status !== 'processing' && status !== 'simulating') return;
    job['duration'] = Math.round((Number(job['duration'] ?? 0) + dt) * 10) / 10;
    if (j.warming) {
      const hs = this.heaters();
      const ready = [0, 1].every((i) => {
        const h = hs[i];
        return !h || Math.abs(Number(h['current']) - Number(h['active'])) < 3;
      });
      job['warmUpDuration'] = Math.round((Number(job['warmUpDuration'] ?? 0) + dt) * 10) / 10;
      if (!ready) return;
      j.warming = false;
    }
    j.printed += dt * (j.simulate ? 20 : 1);
    const frac = Math.min(1, j.printed / j.printTime);
    job['filePosition'] = Math.round(frac * j.size);
    const layer = Math.max(1, Math.ceil(frac * j.layers));
    job['layer'] = layer;
    const left = Math.max(0, j.printTime - j.printed);
    job['timesLeft'] = {
      file: Math.round(left * 1.05),
      filament: Math.round(left * 0.98),
      slicer: Math.round(left),
    };
    const a = frac * j.layers * Math.PI * 2 * 3;
    const pos = [115 + 40 * Math.cos(a), 105 + 30 * Math.sin(a), layer * j.layerHeight];
    this.axes().forEach((ax, i) => {
      const v = Math.round((pos[i] ?? 0) * 1000) / 1000;
      ax['userPosition'] = v;
      ax['machinePosition'] = v;
    });
    // Part cooling on from layer 2 (as slicers do); the hotend fan follows its heater (>45 °C).
    this.setFan(0, j.simulate || layer < 2 ? 0 : 1);
    const ex = arr(o(this.model['move'])['extruders'])[0];
    if (isObject(ex)) ex['position'] = Math.round(frac * 800 * 10) / 10;
    if (frac >= 1) this.finishJob('done');
  }

  // ------------------------------------------------------------------ demo

  /**
   * Start the demo: a real print of a job file on the simulated card (heaters warm up, then the
   * layers advance over about four minutes), repeated while the demo runs. Works only on the
   * simulator's own state, as a person at the machine starting it from the panel would: nothing
   * goes through the console's commands. Runs again when the machine is busy: it waits for idle.
   */
  startDemo(): void {
    const path = this.fs.get(DEMO_FILE) ? DEMO_FILE : this.firstJobFile();
    if (!path) return;
    this.demo = { path, nextAt: this.now() };
    if (!this.job && this.status === 'idle') this.startDemoJob();
  }

  get demoRunning(): boolean {
    return this.demo !== null;
  }

  private startDemoJob(): void {
    const d = this.demo;
    if (!d) return;
    // The file may have been deleted or renamed meanwhile: take another one, or stop.
    const path = this.fs.get(d.path) ? d.path : this.firstJobFile();
    if (!path) {
      this.demo = null;
      return;
    }
    d.path = path;
    const err = this.startJob(path, false);
    if (err) {
      this.demo = null;
      this.message(1, `Demo: ${err}`);
    }
    this.flush();
  }

  private firstJobFile(): string | null {
    for (const p of this.fs.files.keys()) if (p.startsWith('0:/gcodes/') && /\.g(code)?$/i.test(p)) return p;
    return null;
  }
}

/** The demo print (on the seeded card) and the idle time between two runs. */
const DEMO_FILE = '0:/gcodes/bracket.gcode';
const DEMO_PAUSE_MS = 20_000;

const MODE_TEXT: Record<number, string> = {
  0: 'Heating the bed, please wait…',
  1: 'Nozzle wipe finished.',
  2: 'Jog the nozzle to touch the paper, then press OK.',
  3: 'Filament runout detected. Load new filament and continue?',
  4: 'Which filament is loaded?',
  5: 'How many copies?',
  6: 'Z offset (mm)?',
  7: 'Name for this part?',
};
