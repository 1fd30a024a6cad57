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
import {
  board3,
  board3StatusSchema,
  board3Texts,
  loadBoard3,
  moduleOf,
  modulePathOf,
  moduleSchema,
  sectionOf,
  simFlatSchema,
  SMART_PLUG_DEFAULTS,
  toModuleValues,
  type FlatValues,
} from './board';
import { parseLine, sampleGcode } from './gcode';
import { adaImage, validateConfig, validateToSchema, type KeyError } from './validate';
import type { WireNode } from '../wire';

/**
 * A simulated Prunt Board 3 (everything here is simulated). It serves either API generation:
 * - 'module': the document's API (module schema derived from the exact Board 3 schema, see board.ts),
 * - 'flat': the deployed 2025 API with the exact fixtures.
 * Time passes in ticks of `tickMs` (50 ms, the real status tick); each socket gets every Nth tick
 * where N is the divisor it sent. Uploaded files run line by line: positions and temperatures move.
 */

export type PruntApiGeneration = 'module' | 'flat';

export interface PruntSimOptions extends SimOptions {
  api?: PruntApiGeneration;
  /** G-code lines executed per tick while a file runs. */
  linesPerTick?: number;
}

type Startup = 'Done' | 'Update_Running' | 'Update_Required' | 'Waiting';

interface Client {
  sock: SimSocket;
  divisor: number;
  count: number;
}

interface Job {
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
const DEMO_IDLE_MS = 15_000;

const AXES = ['X_AXIS', 'Y_AXIS', 'Z_AXIS', 'E_AXIS'] as const;
const THERMISTORS = ['THERMISTOR_1', 'THERMISTOR_2', 'THERMISTOR_3', 'THERMISTOR_4'] as const;
const HEATERS = ['HEATER_1', 'HEATER_2', 'HEATER_3'] as const;
const LASER_ERROR =
  'raised PRUNT_BOARD_3_SERVER.MY_CONTROLLER.MY_GCODE_HANDLER.MY_GCODE_PARSER.BAD_LINE : This board does not support lasers. Laser commands can not be used.\n';

/** Ada `'Image` of a float: leading space for positive numbers. */
function ada(n: number): string {
  return (n < 0 ? '-' : ' ') + adaImage(Math.abs(n));
}

export class PruntSimulator implements Simulator {
  readonly kind = 'prunt' as const;
  readonly api: PruntApiGeneration;
  /** Resolves when the board data is loaded (lazily, see board.ts); HTTP waits for it. */
  readonly ready: Promise<void>;
  private loaded = false;
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
  private readonly clients = new Set<Client>();
  private readonly timer: ReturnType<typeof setInterval>;
  private readonly now: () => number;
  private readonly tickMs: number;
  private readonly linesPerTick: number;
  private bootAt: number;
  /** Seconds of host uptime at our boot (the fixture's " 86012.004567890"). */
  private uptimeAtBoot = 86012.00456789;
  private waitTicks = 0;
  private updateTicks = 0;
  private commandSeq = 6;
  private moduleSchemaText: string | null = null;
  /** The "demo" control is on: idle ticks since the demo job last ended. */
  private demo: { idleTicks: number } | null = null;

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

  // --- HTTP --------------------------------------------------------------------------------------

  async fetch(req: Request, fullPath: string): Promise<Response> {
    await this.ready;
    const { pathname } = splitPath(fullPath);
    const method = req.method.toUpperCase();
    const route = `${method} ${pathname}`;
    switch (route) {
      case 'GET /config/schema':
        return this.api === 'flat'
          ? textResponse(board3Texts().CONFIG_SCHEMA_TEXT, 200, 'application/json')
          : textResponse(this.moduleSchema(), 200, 'application/json');
      case 'GET /config/values':
        return jsonResponse(this.getValues());
      case 'POST /config/values':
        return this.postValues(await req.text());
      case 'GET /status/schema':
        return this.api === 'flat'
          ? textResponse(board3Texts().STATUS_SCHEMA_TEXT, 200, 'application/json')
          : jsonResponse(MODULE_STATUS_SCHEMA);
      case 'GET /status/values':
        return textResponse(
          this.api === 'flat' ? `{"Status":${this.flatStatusText()}}` : JSON.stringify(this.moduleStatus()),
          200,
          'application/json',
        );
      case 'POST /pause/pause':
        this.paused = true;
        this.log('Pause requested.');
        return new Response(null, { status: 204 });
      case 'POST /pause/resume':
        this.paused = false;
        this.log('Resume requested.');
        return new Response(null, { status: 204 });
      case 'POST /run-file':
        return this.runFile((await req.text()).trim());
      case 'POST /run-command':
        return this.runCommand(await req.text());
      case 'POST /reload-server':
        // Answer first, then restart (the real host restarts after replying).
        setTimeout(() => this.restart(), 0);
        return new Response(null, { status: 204 });
      case 'POST /allow-firmware-update':
        if (this.startup === 'Update_Required') {
          this.startup = 'Update_Running';
          this.updateTicks = 40;
          this.log('Firmware update allowed by user.');
        }
        return new Response(null, { status: 204 });
      case 'GET /uploads':
      case 'GET /uploads/':
        return jsonResponse([...this.uploads.keys()]);
    }
    if (this.api === 'module' && route === 'POST /cancel') {
      // sim: an operator's cancel also ends the demo loop (someone is at the machine now).
      this.demo = null;
      if (this.job) {
        this.log(`Cancelled file ${this.job.file}.`);
        this.job = null;
        this.paused = false;
      }
      return new Response(null, { status: 204 });
    }
    const updatePath = this.api === 'module' ? '/update-check' : '/update_check';
    if (route === `GET ${updatePath}`) {
      if (this.update.timesOut) return textResponse('Update check timed out.', 500);
      return jsonResponse({ Available: this.update.available, URL: this.update.url });
    }
    if (pathname.startsWith('/uploads/')) {
      const name = decodeURIComponent(pathname.slice('/uploads/'.length));
      if (!name || name.includes('/') || name.includes('..')) return textResponse('Invalid file name.', 500);
      if (method === 'GET') {
        const f = this.uploads.get(name);
        return f === undefined
          ? textResponse('Not found.', 404)
          : textResponse(f, 200, 'application/octet-stream');
      }
      if (method === 'PUT') {
        this.uploads.set(name, await req.text());
        this.log(`Uploaded ${name}.`);
        return new Response(null, { status: 204 });
      }
    }
    if (method === 'GET' && pathname.startsWith('/extras/images/')) {
      const name = pathname.split('/').pop() ?? '';
      return textResponse(placeholderImage(name), 200, 'image/svg+xml');
    }
    return textResponse('Not found.', 404);
  }

  private moduleSchema(): string {
    this.moduleSchemaText ??= JSON.stringify(moduleSchema());
    return this.moduleSchemaText;
  }

  private getValues(): unknown {
    const errors = validateConfig(this.values);
    if (this.api === 'flat') {
      // A read: Prunt's Get_Values writes nothing (its file is written at start and by a save).
      this.configReads++;
      return { Values: this.values, Errors: errors };
    }
    return { Values: toModuleValues(this.values), Errors: this.toPathErrors(errors) };
  }

  private toPathErrors(errors: KeyError[]): Array<{ Path: string[]; Message: string }> {
    return errors.map((e) => ({ Path: modulePathOf(e.Key), Message: e.Message }));
  }

  private postValues(text: string): Response {
    let body: unknown;
    try {
      body = JSON.parse(text);
    } catch {
      return textResponse('Invalid JSON in request body.', 500); // sim: the text is not in the sources
    }
    if (!body || typeof body !== 'object' || Array.isArray(body))
      return textResponse('Request body must be a JSON object.', 500);
    let patch: Record<string, unknown>;
    const structural: Array<{ Path: string[]; Message: string }> = [];
    if (this.api === 'flat') patch = body as Record<string, unknown>;
    else {
      const r = this.flattenModulePatch(body as Record<string, unknown>);
      patch = r.patch;
      structural.push(...r.errors);
    }
    const schemaErrors = validateToSchema(simFlatSchema(this.api), patch, this.values);
    if (schemaErrors.length || structural.length) {
      // All or nothing: the values are echoed unchanged.
      if (this.api === 'flat') return jsonResponse({ Values: this.values, Errors: schemaErrors });
      return jsonResponse({
        Values: toModuleValues(this.values),
        Errors: [...structural, ...this.toPathErrors(schemaErrors)],
      });
    }
    this.values = { ...this.values, ...(patch as FlatValues) };
    this.log('Config saved.');
    return jsonResponse(this.getValuesAfterSave());
  }

  private getValuesAfterSave(): unknown {
    const errors = validateConfig(this.values);
    if (this.api === 'flat') return { Values: this.values, Errors: errors };
    return { Values: toModuleValues(this.values), Errors: this.toPathErrors(errors) };
  }

  /** Module patch → flat keys; version fields are required (document: "POST /config/values"). */
  private flattenModulePatch(body: Record<string, unknown>): {
    patch: Record<string, unknown>;
    errors: Array<{ Path: string[]; Message: string }>;
  } {
    const errors: Array<{ Path: string[]; Message: string }> = [];
    const patch: Record<string, unknown> = {};
    const schema = simFlatSchema('module');
    if (body['Prunt config version'] !== 1) {
      errors.push({
        Path: ['Prunt config version'],
        Message: `${'Data does not match schema, no values will be saved: '}Prunt config version must be 1.`,
      });
    }
    const config = body['Config'];
    if (config !== undefined && (typeof config !== 'object' || config === null)) {
      errors.push({
        Path: ['Config'],
        Message: 'Data does not match schema, no values will be saved: Config must be an object.',
      });
      return { patch, errors };
    }
    for (const [module, m] of Object.entries((config ?? {}) as Record<string, unknown>)) {
      const section = sectionOf(module);
      const node = schema[section];
      const mod = (m ?? {}) as Record<string, unknown>;
      if (!node || moduleOf(section) !== module) {
        errors.push({
          Path: ['Config', module],
          Message:
            'Data does not match schema, no values will be saved: Module is not a recognised module name.',
        });
        continue;
      }
      if (mod['Version'] !== 1) {
        errors.push({
          Path: ['Config', module, 'Version'],
          Message:
            'Data does not match schema, no values will be saved: Module version is missing or does not match.',
        });
        continue;
      }
      const cfg = (mod['Config'] ?? {}) as Record<string, unknown>;
      for (const [k, v] of Object.entries(cfg)) {
        if (k !== section)
          patch[`${section}$${k}`] = v; // unknown property: reported by the schema check
        else flattenInto(node, section, v, patch);
      }
    }
    return { patch, errors };
  }

  private runFile(name: string): Response {
    const file = name.replace(/^uploads\//, '');
    if (this.job) return textResponse('Can not run file while another file is running.', 500);
    const text = this.uploads.get(file);
    if (text === undefined) return textResponse('File does not exist.', 500); // sim: text not in the sources
    this.job = { file, lines: text.split('\n'), line: 0 };
    this.paused = false;
    this.log(`Running file ${file}.`);
    return new Response(null, { status: 204 });
  }

  private runCommand(command: string): Response {
    const cmd = command.trim();
    if (this.job) return textResponse('Can not run command while a file is running.', 500); // sim: style of the run-file text
    const id = String(++this.commandSeq);
    const result = this.execute(cmd);
    if (this.api === 'flat') {
      if (result.error) this.log(`Error parsing manual command (${cmd}): ${result.error}`);
      return new Response(null, { status: 204 });
    }
    // Newer servers: an ID now, then Gcode_Command messages on the socket.
    setTimeout(() => {
      this.broadcast(JSON.stringify({ Gcode_Command: { ID: id, Kind: 'Running' } }));
      if (result.output)
        this.broadcast(JSON.stringify({ Gcode_Command: { ID: id, Kind: 'Output', Message: result.output } }));
      this.broadcast(
        JSON.stringify({
          Gcode_Command: result.error
            ? { ID: id, Kind: 'Failed', Message: result.error.trim() }
            : { ID: id, Kind: 'Completed' },
        }),
      );
    }, this.tickMs);
    return jsonResponse({ ID: id });
  }

  /** Execute one line (manual command or file line). */
  private execute(line: string): { output?: string; error?: string } {
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

  private restart(): void {
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

  private log(text: string): void {
    this.broadcast(JSON.stringify({ Log: text }));
  }

  private broadcast(text: string): void {
    for (const c of this.clients) c.sock.send(text);
  }

  // --- Status ------------------------------------------------------------------------------------

  private flatStatusText(): string {
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
  private startDemoJob(): void {
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

  controls(): SimControl[] {
    const list: SimControl[] = [
      {
        id: 'demo',
        label: 'Start a demo job',
        run: () => {
          if (this.demo) return;
          // Started before the board data loaded or during startup: the tick loop starts it.
          this.demo = { idleTicks: Math.ceil(DEMO_IDLE_MS / this.tickMs) };
          if (this.loaded) this.startDemoJob();
        },
      },
      {
        id: 'require-update',
        label: 'Firmware update required (board firmware out of date)',
        run: () => {
          this.startup = 'Update_Required';
          this.log('Board firmware does not match the server: update required.');
        },
      },
      {
        id: 'update-available',
        label: 'A host software update becomes available',
        run: () => {
          this.update = {
            available: true,
            url: 'https://github.com/Prunt3D/prunt_board_3_software/releases/tag/v1.7.2',
            timesOut: false,
          };
        },
      },
      {
        id: 'update-timeout',
        label: 'Update check times out',
        run: () => void (this.update.timesOut = true),
      },
      { id: 'reload', label: 'Server restarts (power blip)', run: () => this.restart() },
    ];
    if (this.api === 'module') {
      list.push({
        id: 'exception',
        label: 'Recoverable server exception',
        run: () => {
          this.exception = { Message: 'raised CONSTRAINT_ERROR : example recoverable error\n', Fatal: false };
        },
      });
      list.push({
        id: 'clear-exception',
        label: 'Clear server exception',
        run: () => void (this.exception = null),
      });
    }
    return list;
  }

  dispose(): void {
    clearInterval(this.timer);
    for (const c of [...this.clients]) c.sock.close(1001, 'simulator disposed');
    this.clients.clear();
  }
}

function flattenInto(n: WireNode, key: string, v: unknown, out: Record<string, unknown>): void {
  switch (n.Kind) {
    case 'Sequence':
    case 'Tabbed_Sequence': {
      if (!v || typeof v !== 'object') {
        out[key] = v;
        return;
      }
      for (const [k, c] of Object.entries(v as Record<string, unknown>)) {
        const child = n.Children?.[k];
        if (child) flattenInto(child, `${key}$${k}`, c, out);
        else out[`${key}$${k}`] = c;
      }
      return;
    }
    case 'Variant': {
      const o = (v ?? {}) as Record<string, unknown>;
      if ('Selected' in o) out[key] = o['Selected'];
      for (const [k, c] of Object.entries((o['Children'] ?? {}) as Record<string, unknown>)) {
        const child = n.Children?.[k];
        if (child) flattenInto(child, `${key}$${k}`, c, out);
        else out[`${key}$${k}`] = c;
      }
      return;
    }
    case 'Float_Ratio': {
      const o = (v ?? {}) as Record<string, unknown>;
      if ('Numerator' in o) out[`${key}$Numerator`] = o['Numerator'];
      if ('Denominator' in o) out[`${key}$Denominator`] = o['Denominator'];
      return;
    }
    default:
      out[key] = v;
  }
}

function placeholderImage(name: string): string {
  const safe = name.replace(/[^A-Za-z0-9_.-]/g, '');
  return `<svg xmlns="http://www.w3.org/2000/svg" width="600" height="120" viewBox="0 0 600 120"><rect width="600" height="120" fill="#ddd"/><text x="300" y="65" font-family="sans-serif" font-size="18" text-anchor="middle" fill="#333">Simulated board image: ${safe}</text></svg>`;
}

/**
 * Module API status schema of the simulated board. "Internal Status Reporter" is exact
 * (v2026/status-schema.internal-status-reporter.json); "Thermistors" and "Heaters" are the
 * simulator's stand-ins for the other modules' groups, which the fixtures do not contain.
 */
export const MODULE_STATUS_SCHEMA = {
  Heaters: {
    Power: Object.fromEntries(
      HEATERS.map((h) => [
        h,
        { Kind: 'Real', Unit: '', Description: `Power output of heater ${h} (0 to 1).`, Condition: '' },
      ]),
    ),
  },
  'Internal Status Reporter': {
    Position: Object.fromEntries(
      ['E_AXIS', 'X_AXIS', 'Y_AXIS', 'Z_AXIS'].map((a) => [
        a,
        { Kind: 'Real', Unit: 'mm', Description: `Position of axis ${a}`, Condition: '' },
      ]),
    ),
    'Print status': {
      'Current line': {
        Kind: 'Integer',
        Unit: '',
        Description: 'Current line in g-code file.',
        Condition: '',
      },
      'File name': { Kind: 'String', Unit: '', Description: 'Name of current g-code file.', Condition: '' },
      Paused: {
        Kind: 'Boolean',
        Unit: '',
        Description: 'True if printer is currently paused.',
        Condition: '',
      },
    },
  },
  Thermistors: {
    Temperature: Object.fromEntries(
      THERMISTORS.map((t) => [
        t,
        {
          Kind: 'Real',
          Unit: 'celsius',
          Description: `Temperature of ${t}.`,
          Condition: 'Only present when the thermistor kind is not Disabled.',
        },
      ]),
    ),
  },
};

export function createPruntSimulator(opts: PruntSimOptions): PruntSimulator {
  return new PruntSimulator(opts);
}
