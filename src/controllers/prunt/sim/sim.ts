import { jsonResponse, splitPath, textResponse, type SimControl, type Simulator } from '../../../fleet/sim';
import {
  board3Texts,
  moduleOf,
  modulePathOf,
  moduleSchema,
  sectionOf,
  simFlatSchema,
  toModuleValues,
  type FlatValues,
} from './board';
import { DEMO_IDLE_MS, HEATERS, PruntSimBoard, THERMISTORS, type PruntSimOptions } from './board-state';
import { validateConfig, validateToSchema, type KeyError } from './validate';
import type { WireNode } from '../wire';

/**
 * A simulated Prunt Board 3 (everything here is simulated), either API generation: 'module' (the
 * document's, schema derived from the exact Board 3 schema, board.ts) or 'flat' (the deployed 2025
 * API, exact fixtures). Layers: board-state.ts (state, ticks of `tickMs`, G-code, sockets with
 * their divisors, status frames), this file (HTTP, config values, developer panel).
 */

export type { PruntApiGeneration, PruntSimOptions } from './board-state';

export class PruntSimulator extends PruntSimBoard implements Simulator {
  readonly kind = 'prunt' as const;
  private moduleSchemaText: string | null = null;

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
