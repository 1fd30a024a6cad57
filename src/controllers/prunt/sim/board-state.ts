import type { SimOptions, SimSocket, SimSocketHandler } from '../../../fleet/sim';
import { splitPath } from '../../../fleet/sim';
import { board3, board3StatusSchema, loadBoard3, SMART_PLUG_DEFAULTS, type FlatValues } from './board';
import { parseLine, sampleGcode } from './gcode';
import { adaImage } from './validate';

/**
 * The simulated Prunt board's state and time (sim.ts adds the HTTP surface): ticks of `tickMs`
 * move files line by line, heaters and positions; each socket gets every Nth tick's status frame,
 * N being the divisor it sent.
 */

export type PruntApiGeneration = 'module' | 'flat';

export interface PruntSimOptions extends SimOptions {
  api?: PruntApiGeneration;
  /** G-code lines executed per tick while a file runs. */
  linesPerTick?: number;
}

export type Startup = 'Done' | 'Update_Running' | 'Update_Required' | 'Waiting';

interface Client {
  sock: SimSocket;
  divisor: number;
  count: number;
}

export interface Job {
  file: string;
  lines: string[];
  line: number;
  /** Paced job (the demo): one line every `ticksPerLine` ticks instead of `linesPerTick` per tick. */
  ticksPerLine?: number;
  wait?: number;
}

/** The demo job: a file that runs for about four minutes, then, after a pause, runs again. */
const DEMO_FILE = 'benchy.gcode';
const DEMO_RUN_MS = 4 * 60_000;
export const DEMO_IDLE_MS = 15_000;

export const AXES = ['X_AXIS', 'Y_AXIS', 'Z_AXIS', 'E_AXIS'] as const;
export const THERMISTORS = ['THERMISTOR_1', 'THERMISTOR_2', 'THERMISTOR_3', 'THERMISTOR_4'] as const;
export const HEATERS = ['HEATER_1', 'HEATER_2', 'HEATER_3'] as const;
const LASER_ERROR =
  'raised PRUNT_BOARD_3_SERVER.MY_CONTROLLER.MY_GCODE_HANDLER.MY_GCODE_PARSER.BAD_LINE : This board does not support lasers. Laser commands can not be used.\n';

/** Ada `'Image` of a float: leading space for positive numbers. */
function ada(n: number): string {
  return (n < 0 ? '-' : ' ') + adaImage(Math.abs(n));
}

export abstract class PruntSimBoard {
  readonly api: PruntApiGeneration;
  /** Resolves when the board data is loaded (lazily, see board.ts); HTTP waits for it. */
  readonly ready: Promise<void>;
  protected loaded = false;
  values: FlatValues;
  /** Times the flat API answered GET /config/values (a read: it writes nothing). */
  configReads = 0;
  startup: Startup = 'Done';
  paused = false;
  job: Job | null = null;
  positions: Record<string, number> = { X_AXIS: 117.5, Y_AXIS: 98.25, Z_AXIS: 12.3, E_AXIS: 0 };
  temps: Record<string, number> = { THERMISTOR_1: 24, THERMISTOR_2: 23, THERMISTOR_3: 22, THERMISTOR_4: 22 };
  targets = { hotend: 0, bed: 0 };
  powers: Record<string, number> = { HEATER_1: 0, HEATER_2: 0, HEATER_3: 0 };
  update = { available: false, url: '', timesOut: false };
  exception: { Message: string; Fatal: boolean } | null = null;
  readonly uploads = new Map<string, string>();
  protected readonly clients = new Set<Client>();
  private readonly timer: ReturnType<typeof setInterval>;
  protected readonly now: () => number;
  protected readonly tickMs: number;
  private readonly linesPerTick: number;
  private bootAt: number;
  /** Seconds of host uptime at our boot (the fixture's " 86012.004567890"). */
  private uptimeAtBoot = 86012.00456789;
  private waitTicks = 0;
  protected updateTicks = 0;
  protected commandSeq = 6;
  /** The "demo" control is on: idle ticks since the demo job last ended. */
  protected demo: { idleTicks: number } | null = null;

  constructor(opts: PruntSimOptions) {
    this.api = opts.api ?? 'module';
    this.now = opts.now ?? Date.now;
    this.tickMs = opts.tickMs ?? 50;
    this.linesPerTick = opts.linesPerTick ?? 4;
    this.values = {};
    this.ready = loadBoard3().then(() => {
      this.values = { ...board3().values, ...(this.api === 'module' ? SMART_PLUG_DEFAULTS : {}) };
      this.loaded = true;
    });
    for (const n of ['benchy.gcode', 'calibration_cube.gcode', 'first_layer_test.gcode'])
      this.uploads.set(n, sampleGcode(n));
    this.bootAt = this.now();
    this.timer = setInterval(() => this.tick(), this.tickMs);
  }

  /** Execute one line (manual command or file line). */
  protected execute(line: string): { output?: string; error?: string } {
    const p = parseLine(line);
    if (!p) return {};
    const w = p.words;
    switch (p.code) {
      case 'G0':
      case 'G1':
        for (const [letter, axis] of [
          ['X', 'X_AXIS'],
          ['Y', 'Y_AXIS'],
          ['Z', 'Z_AXIS'],
          ['E', 'E_AXIS'],
        ] as const) {
          const v = w.get(letter);
          if (v !== undefined) this.positions[axis] = v;
        }
        return {};
      case 'G28':
        this.positions = { ...this.positions, X_AXIS: 0, Y_AXIS: 0, Z_AXIS: 0 };
        return {};
      case 'M104':
      case 'M109':
        this.targets.hotend = w.get('S') ?? 0;
        return {};
      case 'M140':
      case 'M190':
        this.targets.bed = w.get('S') ?? 0;
        return {};
      case 'M114':
        return { output: AXES.map((a) => `${a[0]}:${(this.positions[a] ?? 0).toFixed(3)}`).join(' ') };
      case 'M3':
      case 'M4':
      case 'M5':
        return { error: LASER_ERROR };
      default:
        return p.code.startsWith('G') || p.code.startsWith('M')
          ? {}
          : { error: `Unknown command: ${p.code}` };
    }
  }

  // --- World -------------------------------------------------------------------------------------

  private tick(): void {
    if (!this.loaded) return;
    if (this.waitTicks > 0 && --this.waitTicks === 0 && this.startup === 'Waiting') this.startup = 'Done';
    if (this.updateTicks > 0 && --this.updateTicks === 0 && this.startup === 'Update_Running') {
      this.startup = 'Done';
      this.log('Firmware update done.');
    }
    if (this.demo && !this.job && this.startup === 'Done') {
      if (++this.demo.idleTicks * this.tickMs >= DEMO_IDLE_MS) this.startDemoJob();
    }
    const paced = this.job?.ticksPerLine;
    if (this.job && paced && !this.paused && this.startup === 'Done') {
      this.job.wait = (this.job.wait ?? 0) - 1;
      if (this.job.wait <= 0) {
        this.job.wait = paced;
        const line = this.job.lines[this.job.line];
        this.job.line++;
        if (line !== undefined) this.execute(line);
        if (this.job.line >= this.job.lines.length) {
          this.log(`File ${this.job.file} done.`);
          this.job = null;
        }
      }
    } else if (this.job && !this.paused && this.startup === 'Done') {
      for (let i = 0; i < this.linesPerTick && this.job; i++) {
        const line = this.job.lines[this.job.line];
        this.job.line++;
        if (line !== undefined) this.execute(line);
        if (this.job.line >= this.job.lines.length) {
          this.log(`File ${this.job.file} done.`);
          this.job = null;
        }
      }
    }
    // Heaters: a crude first-order model with bang-bang power.
    const dt = this.tickMs / 1000;
    const heat = (th: string, heater: string, target: number, rate: number) => {
      const t = this.temps[th] ?? 22;
      const power = target > 0 && t < target ? Math.min(1, (target - t) / 10 + 0.2) : target > 0 ? 0.15 : 0;
      this.powers[heater] = Math.min(1, power);
      this.temps[th] = t + (power * rate - (t - 22) * 0.02) * dt;
    };
    heat('THERMISTOR_1', 'HEATER_1', this.targets.hotend, 12);
    heat('THERMISTOR_2', 'HEATER_2', this.targets.bed, 3);
    for (const c of this.clients) {
      c.count++;
      if (c.count % c.divisor === 0) c.sock.send(this.tickText());
    }
  }

  private uptime(): number {
    return this.uptimeAtBoot + (this.now() - this.bootAt) / 1000;
  }

  private startTimeText(): string {
    return ` ${this.uptimeAtBoot.toFixed(9)}`;
  }

  protected restart(): void {
    this.log('Server reloading.');
    this.job = null;
    this.paused = false;
    this.uptimeAtBoot = this.uptime() + 0.5;
    this.bootAt = this.now();
    this.startup = 'Waiting';
    this.waitTicks = 20;
    // The process restarts: every socket drops.
    for (const c of [...this.clients]) c.sock.close(1001, 'server reloading');
    this.clients.clear();
  }

  protected log(text: string): void {
    this.broadcast(JSON.stringify({ Log: text }));
  }

  protected broadcast(text: string): void {
    for (const c of this.clients) c.sock.send(text);
  }

  // --- Status ------------------------------------------------------------------------------------

  protected flatStatusText(): string {
    const group = (names: readonly string[], f: (n: string) => string) =>
      `{${names.map((n) => `"${n}":${f(n)}`).join(',')}}`;
    const st = board3StatusSchema();
    const fileName = this.job ? `uploads/${this.job.file}` : '';
    return [
      `{"Time": ${this.uptime().toFixed(9)}`,
      `"Position":${group(AXES, (a) => ada(this.positions[a] ?? 0))}`,
      `"Thermistor_Temperatures":${group(THERMISTORS, (t) => ada(this.temps[t] ?? 0))}`,
      `"Stepper_Temperatures":${group(st['Stepper_Temperatures'] ?? [], () => ada(35))}`,
      `"Board_Probe_Temperatures":${group(st['Board_Probe_Temperatures'] ?? [], () => ada(44.6))}`,
      `"Heater_Powers":${group(HEATERS, (h) => ada(this.powers[h] ?? 0))}`,
      `"Heater_Currents":${group(HEATERS, (h) => ada((this.powers[h] ?? 0) * 1.7))}`,
      `"Switch_Is_High_State":${group(st['Switch_Is_High_State'] ?? [], (s) => (s === 'STEPPER_DIAG_0' ? 'false' : 'true'))}`,
      `"Tachometer_Frequencies":${group(st['Tachometer_Frequencies'] ?? [], (f) => ada(f === 'FAN_2' ? 193.3 : 0))}`,
      `"StallGuard_Values":${group(st['StallGuard_Values'] ?? [], () => ' 0')}`,
      `"Stepgen_Is_Paused":${this.paused}`,
      `"Current_File_Name":${JSON.stringify(fileName)}`,
      `"Current_File_Line": ${this.job?.line ?? 0}`,
      `"Startup":"${this.startup}"}`,
    ].join(',');
  }

  moduleStatus(): Record<string, Record<string, Record<string, number | boolean | string>>> {
    const temps: Record<string, number> = {};
    // THERMISTOR_3/4 are "Disabled" in the example config: absent, as their Condition says.
    for (const t of ['THERMISTOR_1', 'THERMISTOR_2']) temps[t] = this.temps[t] ?? 0;
    // Condition "" (always present): an idle printer reports an empty name and line 0.
    const print: Record<string, number | boolean | string> = {
      'File name': this.job ? `uploads/${this.job.file}` : '',
      'Current line': this.job?.line ?? 0,
      Paused: this.paused,
    };
    return {
      'Internal Status Reporter': {
        Position: Object.fromEntries(AXES.map((a) => [a, this.positions[a] ?? 0])),
        'Print status': print,
      },
      Thermistors: { Temperature: temps },
      Heaters: { Power: Object.fromEntries(HEATERS.map((h) => [h, this.powers[h] ?? 0])) },
    };
  }

  private tickText(): string {
    if (this.api === 'flat') return `{"Status":${this.flatStatusText()}}`;
    const plug = {
      Enabled: this.values['Smart plug$Enabled'] === true,
      Host: String(this.values['Smart plug$Host'] ?? ''),
      Provider: String(this.values['Smart plug$Provider'] ?? ''),
      Power: 'UNKNOWN',
      Watchdog_Active: false,
      Watchdog_Seconds: 0,
      Busy: false,
      Error: '',
    };
    // The exact spacing of prunt-web_server.adb at 330b4243: ", " between fields, "Startup": "…".
    return `{"Status_Values":${JSON.stringify(this.moduleStatus())}, "Smart_Plug":${JSON.stringify(plug)}, "Server_Exception":${JSON.stringify(this.exception)}, "Startup": "${this.startup}"}`;
  }

  // --- WebSocket ---------------------------------------------------------------------------------

  socket(path: string, sock: SimSocket): SimSocketHandler | null {
    if (splitPath(path).pathname !== '/websocket/everything') return null;
    const client: Client = { sock, divisor: 1, count: 0 };
    this.clients.add(client);
    sock.send(JSON.stringify({ Server_Start_Time: this.startTimeText() }));
    return {
      message: (data) => {
        // "The client is permitted to send a plaintext positive integer to throttle the status updates."
        const t = data.trim();
        if (/^\d+$/.test(t) && Number(t) > 0) {
          client.divisor = Number(t);
          client.count = 0;
        }
      },
      close: () => {
        this.clients.delete(client);
      },
    };
  }

  /** Number of sockets and their divisors (tests). */
  socketDivisors(): number[] {
    return [...this.clients].map((c) => c.divisor);
  }

  /**
   * Start the demo job through the simulator's own state (as an operator at the machine would:
   * no HTTP command, nothing in the audit log). Skipped while a file runs or the server starts.
   */
  protected startDemoJob(): void {
    if (!this.demo) return;
    this.demo.idleTicks = 0;
    if (this.job || this.startup !== 'Done') return;
    const text = this.uploads.get(DEMO_FILE) ?? sampleGcode(DEMO_FILE);
    const lines = text.split('\n');
    const ticksPerLine = Math.max(1, Math.round(DEMO_RUN_MS / this.tickMs / lines.length));
    this.job = { file: DEMO_FILE, lines, line: 0, ticksPerLine, wait: 0 };
    this.paused = false;
    this.log(`Running file ${DEMO_FILE}.`);
  }

  /** The demo loop is on (tests). */
  get demoRunning(): boolean {
    return this.demo !== null;
  }

  dispose(): void {
    clearInterval(this.timer);
    for (const c of [...this.clients]) c.sock.close(1001, 'simulator disposed');
    this.clients.clear();
  }
}
