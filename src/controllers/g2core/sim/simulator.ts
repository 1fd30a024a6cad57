import {
  jsonResponse,
  splitPath,
  type SimControl,
  type SimOptions,
  type Simulator,
} from '../../../fleet/sim';
import { G2Fail, errorResponse, isRecord, parseFilter, readBody } from './fail';
import { newModel, zeroVec } from './model';
import { G2coreJobs } from './jobs';
import { COMMAND_KEYS } from './settings';

export { DEMO_JOB_NAME, DEMO_PAUSE_MS, demoPocket } from './jobs';

/**
 * A simulated g2core behind the console's REST design (see client.ts for the settled open
 * points). The settings tree is the 100.12 "makeblock" dump from the design's examples
 * (sim/data/config-groups-100.12.json). Time passes on a timer: operations run their lines, moves
 * are interpolated at the feed, homing searches for its switch, dwell waits, feedhold stops and
 * cycle start resumes. Everything here is SIMULATED.
 *
 * Deliberate differences from the dump, each stated so nobody mistakes them for firmware facts:
 *  - soft limits are on (`sl:1`; the dump has 0) so the console's 405 path can be seen;
 *  - the machine powers up 150/100/-30 mm away from its switches (unknown to it until homed).
 *
 * The simulator is one object built in layers, one file each, every layer adding one job to the
 * layer below it:
 *  - state.ts       every field of the simulated controller, and the status report built from them;
 *  - settings.ts    the settings tree: key spellings, reads, filters, validated sets;
 *  - operations.ts  the operation queue and how an operation ends (done, error, kill, alarm);
 *  - motion.ts      time: lines interpreted (gcode.ts) and played out as moves, homing, dwells;
 *  - jobs.ts        the job queue and the demo loop that feeds it;
 *  - this file      the HTTP routes of the REST design and the developer panel's controls.
 * fail.ts holds the status-code error (G2Fail) every layer throws and the routes answer.
 */

/** Default status report fields (settings_default.h) plus machine positions, plane, path, hold and overrides. */
export const SR_FIELDS = [
  'line',
  'posx',
  'posy',
  'posz',
  'posa',
  'mpox',
  'mpoy',
  'mpoz',
  'mpoa',
  'feed',
  'vel',
  'unit',
  'coor',
  'dist',
  'admo',
  'frmo',
  'momo',
  'plan',
  'path',
  'stat',
  'hold',
  'mfo',
  'sso',
];

/** Longest line the simulated firmware accepts (a simulator choice: g2core reads lines into a ~255-byte buffer). */
const MAX_LINE = 254;

export class G2coreSimulator extends G2coreJobs implements Simulator {
  readonly kind = 'g2core' as const;

  // ------------------------------------------------------------------------------ HTTP

  async fetch(req: Request, rawPath: string): Promise<Response> {
    const { pathname, query } = splitPath(rawPath);
    const path = decodeURIComponent(pathname).replace(/\/+$/, '') || '/';
    const method = req.method.toUpperCase();
    try {
      this.tick();
      if (path === '/version' && method === 'GET') return jsonResponse(this.version());
      if (path === '/status_report' && method === 'GET') return this.getStatus(query);
      if (path === '/machine' && method === 'GET') return this.getMachine(query);
      const key = /^\/machine\/(.+)$/.exec(path)?.[1];
      if (key !== undefined && method === 'GET') return this.getKey(key);
      if (key !== undefined && method === 'PUT') return this.putKey(key, await readBody(req));
      if (path === '/operation' && method === 'POST') return this.postOperation(await readBody(req));
      if (path === '/operation' && method === 'GET') return jsonResponse(this.opList());
      const opId = /^\/operation\/([^/]+)$/.exec(path)?.[1];
      if (opId !== undefined && method === 'GET') return jsonResponse(this.opView(this.findOp(opId)));
      if (opId !== undefined && method === 'PUT')
        return this.putOperation(this.findOp(opId), await readBody(req));
      if (path === '/job' && method === 'POST') return await this.postJob(req);
      if (path === '/job' && method === 'GET') return jsonResponse(this.jobList());
      const jobId = /^\/job\/([^/]+)$/.exec(path)?.[1];
      if (jobId !== undefined && method === 'GET') return jsonResponse(this.jobView(this.findJob(jobId)));
      if (jobId !== undefined && method === 'PUT')
        return this.putJob(this.findJob(jobId), await readBody(req));
      if (jobId !== undefined && method === 'DELETE') return this.deleteJob(this.findJob(jobId));
      if (
        ['/version', '/status_report', '/machine', '/operation', '/job'].includes(path) ||
        key ||
        opId ||
        jobId
      ) {
        return errorResponse(106, `${method} is not supported on ${path}`);
      }
      return errorResponse(100, path);
    } catch (e) {
      if (e instanceof G2Fail) return errorResponse(e.code, e.additional);
      throw e;
    }
  }

  private getStatus(query: URLSearchParams): Response {
    const spec = parseFilter(query);
    if (!spec) {
      const st = this.status();
      return jsonResponse(Object.fromEntries(SR_FIELDS.map((k) => [k, st[k]])));
    }
    return jsonResponse(this.select(spec, 'status'));
  }

  private getMachine(query: URLSearchParams): Response {
    if (query.get('shallow') === 'true') {
      return jsonResponse({ value: Object.fromEntries(Object.keys(this.cfg).map((k) => [k, true])) });
    }
    const spec = parseFilter(query);
    if (!spec || Object.keys(spec).length === 0) return jsonResponse({ value: structuredClone(this.cfg) });
    return jsonResponse({ value: this.select(spec, 'machine') });
  }

  private getKey(key: string): Response {
    const k = key.toLowerCase();
    if (COMMAND_KEYS.has(k)) return this.command(k);
    return jsonResponse({ value: this.readValue(key) });
  }

  private command(k: string): Response {
    if (k === 'clear' || k === 'clr') {
      if (this.stat === 13) throw new G2Fail(206, 'PANIC needs a hard reset (^X) or a power cycle');
      if (this.stat === 2 || this.stat === 12) {
        this.stat = 3;
        this.hold = 0;
      }
      return jsonResponse({ value: null });
    }
    if (k === 'alarm') this.raise(2, 18, 'alarm requested');
    if (k === 'shutd') this.raise(12, 5, 'shutdown requested');
    if (k === 'panic') this.raise(13, 6, 'panic requested');
    return jsonResponse({ value: null });
  }

  private putKey(key: string, value: unknown): Response {
    this.validateSet(key, value, false);
    const r = this.resolve(key);
    if (r.kind === 'group') return jsonResponse({ value: { [key]: { ...this.cfg[r.group] } } });
    return jsonResponse({ value: this.readValue(key) });
  }

  private postOperation(body: unknown): Response {
    if (!isRecord(body)) throw new G2Fail(101, 'expected {"optype":…,"value":…}');
    const { optype, value } = body;
    const rejected = this.alarmed();
    if (rejected !== null) throw new G2Fail(rejected, 'clear the alarm first');
    let lines: string[];
    if (optype === 'run') {
      if (typeof value === 'string') lines = value.split(/\r?\n/);
      else if (Array.isArray(value) && value.every((l) => typeof l === 'string')) lines = value as string[];
      else throw new G2Fail(101, 'value must be a string or an array of lines');
      lines = lines.map((l) => l.trim()).filter((l) => l !== '');
      if (lines.length === 0) throw new G2Fail(101, 'no lines to run');
      // A line longer than the firmware's line buffer is status 107 (HTTP 413 in the design's table).
      const long = lines.findIndex((l) => l.length > MAX_LINE);
      if (long >= 0)
        throw new G2Fail(107, `line ${long + 1} has ${lines[long]!.length} characters > ${MAX_LINE}`);
    } else if (optype === 'sendfile') {
      // The same as PUT /job/{id} {"state":"run"}: one job at a time, never behind other motion.
      const job = this.findJob(String(value));
      if (job.state !== 'queued') throw new G2Fail(106, `job ${job.id} is ${job.state}`);
      if (this.currentOp()) throw new G2Fail(106, 'the machine is busy with another operation');
      this.startJob(job);
      return jsonResponse(job.operation, 201);
    } else throw new G2Fail(101, `unknown optype ${JSON.stringify(optype)}`);
    this.dryRun(lines);
    const op = this.addOp('run', value as string[] | string, lines, null);
    return jsonResponse(op.id, 201);
  }

  // ------------------------------------------------------------------------------ controls

  controls(): SimControl[] {
    return [
      { id: 'demo', label: 'Start a demo job', run: () => this.startDemo() },
      {
        id: 'limit',
        label: 'Trip a limit switch (ALARM)',
        run: () => this.raise(2, 203, 'limit switch hit'),
      },
      { id: 'shutdown', label: 'Shutdown input (SHUTDOWN)', run: () => this.raise(12, 5, 'shutdown input') },
      { id: 'panic', label: 'Panic (PANIC)', run: () => this.raise(13, 6, 'panic') },
      {
        id: 'interlock',
        label: 'Open / close the safety interlock',
        run: () => {
          if (this.stat === 11) {
            // Closed again: a job in progress waits in feedhold for a cycle start.
            const op = this.currentOp();
            this.stat = op && op.state === 'run' ? 6 : 3;
            this.hold = this.stat === 6 ? 4 : 0;
          } else if (this.alarmed() === null) {
            this.stat = 11;
            this.vel = 0;
          }
        },
      },
      {
        id: 'reset',
        label: 'Hard reset / power cycle (^X)',
        run: () => {
          this.raise(1, 6, 'reset');
          this.model = newModel();
          this.drift = {
            x: this.drift.x + this.mpos.x,
            y: this.drift.y + this.mpos.y,
            z: this.drift.z + this.mpos.z,
            a: 0,
            b: 0,
            c: 0,
          };
          this.mpos = zeroVec();
          this.line = 0;
        },
      },
    ];
  }
}

export function createG2coreSimulator(opts: SimOptions): Simulator {
  return new G2coreSimulator(opts);
}
