import configGroups from '../sim/data/config-groups-100.12.json' with { type: 'json' };
import { STUCK_IN_RUN } from '../codes';
import { jsonResponse, splitPath, type Simulator } from '../../../fleet/sim';
import { G2Fail, errorResponse, isRecord, parseFilter, readBody } from '../sim/fail';
import { LinkDown, SerialLink, UnsafeBytes, type PortOpener } from './link';
import { isObject, lineProblem, tooLong, type Json, type JsonObject } from './protocol';
import { MAX_JOB_BYTES, Streamer, type SerialJob, type SerialOp, type StreamerEvents } from './streamer';
import { jobView, readJobUpload } from '../sim/job-wire';

/**
 * The g2core REST design (../shared/protocols/g2core-rest-design.txt, as the console settled it in
 * src/controllers/g2core/README.md) served by the gateway from a board on a USB serial port
 * (issue 19). It offers the same `fetch(req, path)` as the in-process simulators, so the proxy
 * routes a serial machine exactly as a simulated one: access control, audit and sharing happen
 * before a request gets here. The browser side is unchanged.
 *
 * When the board is not connected every request that needs it answers 503 with a gateway error
 * body (`{"error":…,"gateway":true}`) that names the reason (unplugged, port held by another
 * program, reconnecting, reset): the page shows it as the link state. Nothing is queued for later.
 *
 * Not a simulator: `simulated` stays false for these machines. Node-only.
 */

/** The config groups g2core builds have (100.12 dump): answers `GET /machine?shallow=true`. */
const GROUPS = Object.keys(configGroups);

/** Settings that may change while the machine moves: the overrides. */
const OVERRIDES = new Set(['mfo', 'mto', 'sso']);
const COMMAND_KEYS = new Set(['clear', 'clr', 'alarm', 'shutd', 'panic']);
const MOVING = new Set([5, 6, 7, 8, 9, 10]);
const MAX_LINES = 10_000;

/**
 * Liveness while no operation runs (idle, held): filtered status reports say nothing while
 * nothing changes, so a board quiet for `PROBE_AFTER_MS` is asked for a status report (a JSON
 * request, answered out of band: it never disturbs a job or a hold); quiet for `SILENT_MS`, it is
 * shown as not answering. While an operation runs, the watchdog ("stuck in run") does this.
 */
const PROBE_AFTER_MS = 2000;
const SILENT_MS = 5000;

/**
 * Sent on every connect and after every reset, and logged: filtered status reports at the
 * captures' rate (a setting the board keeps), then a full report to start from.
 */
const SETUP: Array<[string, Json]> = [
  ['sv', 1],
  ['si', 250],
  ['sr', null],
];

export interface SerialBridgeOptions {
  id: string;
  name: string;
  /** Device path, or "auto". */
  serial: string;
  baudRate: number;
  opener: PortOpener;
  watchdogMs?: number;
  window?: number;
  retryMs?: number;
  bannerWaitMs?: number;
  events?: StreamerEvents;
  now?: () => number;
  setTimeout?: (fn: () => void, ms: number) => unknown;
  clearTimeout?: (t: unknown) => void;
}

/** `/machine/x/vm`, `/machine/x.vm`, `/machine/xvm`, `/machine/sys/ct` → the firmware's token. */
export function firmwareKey(raw: string): string {
  const parts = raw
    .toLowerCase()
    .split(/[/.]/)
    .filter((p) => p !== '');
  while (parts.length > 1 && parts[0] === 'sys') parts.shift();
  return parts.join('');
}

/** Only keys made of letters and digits reach the board (no JSON or line tricks in a path). */
function checkKey(k: string): void {
  if (!/^[a-z0-9]{1,16}$/.test(k)) throw new G2Fail(100, k.slice(0, 40));
  if (k === 'gc' || k === 'gc2') throw new G2Fail(106, 'G-code goes through POST /operation');
}

/**
 * The board cannot answer: the gateway's own failure, marked as the proxy marks its own
 * (`X-Shopdeck-Gateway: error`, `gateway: true`), so the page and the watch read it as the link.
 */
function gatewayDown(words: string): Response {
  const r = jsonResponse({ error: words, gateway: true }, 503);
  r.headers.set('X-Shopdeck-Gateway', 'error');
  return r;
}

export class G2coreSerialBridge implements Simulator {
  readonly kind = 'g2core' as const;
  readonly link: SerialLink;
  readonly streamer: Streamer;
  private readonly now: () => number;
  private readonly ct: (t: unknown) => void;
  private livenessTimer: unknown = null;
  private probing = false;

  constructor(private readonly o: SerialBridgeOptions) {
    const now = o.now ?? Date.now;
    const st = o.setTimeout ?? ((fn: () => void, ms: number) => setTimeout(fn, ms));
    const ct = o.clearTimeout ?? ((t: unknown) => clearTimeout(t as ReturnType<typeof setTimeout>));
    this.now = now;
    this.ct = ct;
    this.link = new SerialLink({
      path: o.serial,
      baudRate: o.baudRate,
      opener: o.opener,
      window: o.window,
      retryMs: o.retryMs,
      bannerWaitMs: o.bannerWaitMs,
      setup: SETUP,
      now,
      setTimeout: st,
      clearTimeout: ct,
    });
    const events = o.events ?? { event: () => undefined };
    this.streamer = new Streamer({
      link: this.link,
      watchdogMs: o.watchdogMs ?? 10_000,
      events,
      now,
      setTimeout: st,
      clearTimeout: ct,
    });
    let last = '';
    this.link.listen({
      state: (s) => {
        const setup = SETUP.map(([k, v]) => `${k} ${String(v)}`).join(', ');
        const words =
          s.state === 'online'
            ? `online on ${this.link.device ?? o.serial} (set up: ${setup})`
            : this.link.downWords();
        if (words !== last)
          events.event(
            s.state === 'online' || s.state === 'connecting' ? 'info' : 'warn',
            `${o.name}: ${words}`,
          );
        last = words;
      },
    });
    this.link.start();
    const tick = (): void => {
      this.livenessTimer = st(() => {
        this.liveness();
        tick();
      }, 1000);
    };
    tick();
  }

  dispose(): void {
    if (this.livenessTimer !== null) this.ct(this.livenessTimer);
    this.livenessTimer = null;
    this.streamer.dispose();
    void this.link.stop();
  }

  /** No operation runs (idle or held): the watchdog does not watch, this does. */
  private watchedHere(): boolean {
    return this.streamer.current()?.state !== 'run';
  }

  /** A quiet board, idle or held, is asked for a status report (out of band: a job is not disturbed). */
  private liveness(): void {
    if (!this.link.online || this.probing || !this.watchedHere()) return;
    if (this.now() - this.link.lastHeard < PROBE_AFTER_MS) return;
    this.probing = true;
    this.link
      .request('sr', null)
      .catch(() => undefined)
      .finally(() => {
        this.probing = false;
      });
  }

  async fetch(req: Request, rawPath: string): Promise<Response> {
    const { pathname, query } = splitPath(rawPath);
    let path: string;
    try {
      path = decodeURIComponent(pathname).replace(/\/+$/, '') || '/';
    } catch {
      return errorResponse(100, 'bad path');
    }
    const method = req.method.toUpperCase();
    try {
      return await this.route(req, method, path, query);
    } catch (e) {
      if (e instanceof G2Fail) return errorResponse(e.code, e.additional);
      if (e instanceof LinkDown) return gatewayDown(`${this.o.name}: ${e.message}`);
      if (e instanceof UnsafeBytes) return errorResponse(101, e.message);
      throw e;
    }
  }

  private async route(req: Request, method: string, path: string, query: URLSearchParams): Promise<Response> {
    const s = this.streamer;
    if (path === '/version' && method === 'GET') return jsonResponse(await this.version());
    if (path === '/status_report' && method === 'GET') return this.statusReport(query);
    if (path === '/machine' && method === 'GET') return this.machine(query);
    if (path === '/board/reset' && method === 'POST') {
      s.resetBoard();
      return jsonResponse({ value: 'reset sent' });
    }
    const key = /^\/machine\/(.+)$/.exec(path)?.[1];
    if (key !== undefined && method === 'GET') return this.getKey(firmwareKey(key));
    if (key !== undefined && method === 'PUT') return this.putKey(firmwareKey(key), await readBody(req));
    if (path === '/operation' && method === 'POST') return this.postOperation(await readBody(req));
    if (path === '/operation' && method === 'GET') return jsonResponse(this.opList());
    const opId = /^\/operation\/([^/]+)$/.exec(path)?.[1];
    if (opId !== undefined && method === 'GET') return jsonResponse(this.opView(this.findOp(opId)));
    if (opId !== undefined && method === 'PUT') {
      const op = this.findOp(opId);
      const body = await readBody(req);
      const want = isRecord(body) ? body.opstate : undefined;
      if (want === 'pause') s.pause(op);
      else if (want === 'run') s.resume(op);
      else if (want === 'kill') s.kill(op);
      else throw new G2Fail(101, 'opstate must be "pause", "run" or "kill"');
      return jsonResponse(this.opView(op));
    }
    if (path === '/job' && method === 'POST') return this.postJob(req);
    if (path === '/job' && method === 'GET') return jsonResponse(s.jobOrder().map((j) => this.jobView(j)));
    const jobId = /^\/job\/([^/]+)$/.exec(path)?.[1];
    if (jobId !== undefined && method === 'GET') return jsonResponse(this.jobView(this.findJob(jobId)));
    if (jobId !== undefined && method === 'PUT') return this.putJob(this.findJob(jobId), await readBody(req));
    if (jobId !== undefined && method === 'DELETE') {
      s.deleteJob(this.findJob(jobId));
      return new Response(null, { status: 204 });
    }
    if (
      ['/version', '/status_report', '/machine', '/operation', '/job'].includes(path) ||
      key ||
      opId ||
      jobId
    )
      throw new G2Fail(106, `${method} is not supported on ${path}`);
    throw new G2Fail(100, path.slice(0, 80));
  }

  // ------------------------------------------------------------------------------ reads

  /** A request to the board; a non-zero status is the REST error of that code. */
  private async ask(key: string, value: Json): Promise<Json> {
    const reply = await this.link.request(key, value);
    if (reply.status !== 0 && reply.status !== 3 && reply.status !== 4) throw new G2Fail(reply.status, key);
    const k = Object.keys(reply.r).find((x) => x.toLowerCase() === key);
    return k === undefined ? null : (reply.r[k] ?? null);
  }

  private requireOnline(): void {
    if (!this.link.online) throw new LinkDown(this.link.downWords());
  }

  private async version(): Promise<JsonObject> {
    this.requireOnline();
    const b = this.link.banner;
    if (b) return b;
    const sys = await this.ask('sys', null);
    const out: JsonObject = {};
    if (isObject(sys))
      for (const k of ['fv', 'fb', 'fbs', 'fbc', 'hp', 'hv', 'id']) if (k in sys) out[k] = sys[k]!;
    return out;
  }

  private statusReport(query: URLSearchParams): Response {
    this.requireOnline();
    const stuck = this.streamer.stuck;
    if (stuck) {
      return gatewayDown(
        `${this.o.name}: the board has sent nothing since line ${stuck.line} while running (${STUCK_IN_RUN}). A supervisor can reset the board (POST /machines/${this.o.id}/board/reset)`,
      );
    }
    const quiet = this.now() - this.link.lastHeard;
    if (this.watchedHere() && quiet >= SILENT_MS)
      return gatewayDown(
        `${this.o.name}: the board has not answered for ${Math.floor(quiet / 1000)} s (it was asked for a status report): hung or busy; its state is not known`,
      );
    const sr = this.streamer.sr;
    if (Object.keys(sr).length === 0)
      return gatewayDown(`${this.o.name}: waiting for the board's first status report`);
    const spec = parseFilter(query);
    if (!spec) return jsonResponse(sr);
    const out: Record<string, unknown> = {};
    for (const [k, want] of Object.entries(spec)) {
      if (!(k in sr)) continue;
      if (want === null || want !== sr[k]) out[k] = sr[k];
    }
    return jsonResponse(out);
  }

  private async machine(query: URLSearchParams): Promise<Response> {
    this.requireOnline();
    if (query.get('shallow') === 'true')
      return jsonResponse({ value: Object.fromEntries(GROUPS.map((g) => [g, true])) });
    const spec = parseFilter(query) ?? Object.fromEntries(GROUPS.map((g) => [g, null]));
    const keys = Object.keys(spec);
    if (keys.length > GROUPS.length + 20) throw new G2Fail(107, 'too many keys in one filter');
    const whole = parseFilter(query) === null;
    const asked = keys.map((raw) => {
      const k = firmwareKey(raw);
      checkKey(k);
      if (COMMAND_KEYS.has(k)) throw new G2Fail(106, `${k} is a command, not a value`);
      return { raw, k };
    });
    // All asked at once: the link sends them as JSON requests, each answer matched by its key.
    const values = await Promise.all(
      asked.map(({ k }) =>
        this.ask(k, null).catch((e: unknown) => {
          // The whole tree skips groups this build does not have.
          if (whole && e instanceof G2Fail && e.code === 100) return undefined;
          throw e;
        }),
      ),
    );
    const out: Record<string, Json> = {};
    asked.forEach(({ raw }, i) => {
      const v = values[i];
      if (v === undefined) return;
      const want = spec[raw];
      if (isObject(want) && isObject(v)) {
        const sub: JsonObject = {};
        for (const [sk, sw] of Object.entries(want))
          if (sk in v && (sw === null || sw !== v[sk])) sub[sk] = v[sk]!;
        out[raw] = sub;
      } else if (want === null || want === undefined || want !== v) out[raw] = v;
    });
    return jsonResponse({ value: out });
  }

  private async getKey(k: string): Promise<Response> {
    checkKey(k);
    return jsonResponse({ value: await this.ask(k, null) });
  }

  private async putKey(k: string, value: unknown): Promise<Response> {
    checkKey(k);
    if (COMMAND_KEYS.has(k)) throw new G2Fail(106, `${k} is a command: GET /machine/${k}`);
    const stat = this.streamer.sr.stat;
    if (!OVERRIDES.has(k) && typeof stat === 'number' && MOVING.has(stat))
      throw new G2Fail(106, 'settings cannot change while the machine moves');
    if (!isJson(value)) throw new G2Fail(101, 'not a JSON value');
    const problem = lineProblem(JSON.stringify({ [k]: value }));
    if (problem) throw new G2Fail(tooLong(problem) ? 107 : 101, `the value ${problem}`);
    const v = await this.ask(k, value);
    return jsonResponse({ value: GROUPS.includes(k) ? { [k]: v } : v });
  }

  // ------------------------------------------------------------------------------ operations

  private postOperation(body: unknown): Response {
    if (!isRecord(body)) throw new G2Fail(101, 'expected {"optype":…,"value":…}');
    const { optype, value } = body;
    if (optype === 'sendfile') {
      const op = this.streamer.startJob(this.findJob(String(value)));
      return jsonResponse(op.id, 201);
    }
    if (optype !== 'run') throw new G2Fail(101, `unknown optype ${JSON.stringify(optype).slice(0, 40)}`);
    let lines: string[];
    if (typeof value === 'string') lines = value.split(/\r?\n/);
    else if (Array.isArray(value) && value.every((l) => typeof l === 'string')) lines = value as string[];
    else throw new G2Fail(101, 'value must be a string or an array of lines');
    // Numbered as sent: an empty line keeps its number, so a refusal names the line the user wrote.
    if (lines.every((l) => l.trim() === '')) throw new G2Fail(101, 'no lines to run');
    if (lines.length > MAX_LINES) throw new G2Fail(10, `more than ${MAX_LINES} lines: upload a job`);
    const op = this.streamer.addOperation(value as string[] | string, lines);
    return jsonResponse(op.id, 201);
  }

  private findOp(id: string): SerialOp {
    const op = this.streamer.ops.get(Number(id));
    if (!op) throw new G2Fail(100, `no operation ${id.slice(0, 20)}`);
    return op;
  }

  private opView(op: SerialOp): Record<string, unknown> {
    return {
      id: op.id,
      optype: op.optype,
      opstate: op.state,
      // A job's operation carries its job id, not its lines (they can be megabytes).
      value: op.value,
      line: op.done,
      ...(op.error ? { error: op.error } : {}),
      ...(op.r.length ? { r: op.r } : {}),
    };
  }

  private opList(): Record<string, unknown>[] {
    const all = [...this.streamer.ops.values()];
    const active = all.filter((o) => o.state === 'run' || o.state === 'pause' || o.state === 'pend');
    const ended = all
      .filter((o) => !active.includes(o))
      .slice(-20)
      .reverse();
    return [...active, ...ended].map((o) => this.opView(o));
  }

  // ------------------------------------------------------------------------------ jobs

  private async postJob(req: Request): Promise<Response> {
    const { name, text } = await readJobUpload(req, MAX_JOB_BYTES);
    return jsonResponse(this.streamer.addJob(name, text).id, 201);
  }

  private findJob(id: string): SerialJob {
    const job = this.streamer.jobs.get(Number(id));
    if (!job) throw new G2Fail(100, `no job ${id.slice(0, 20)}`);
    return job;
  }

  private jobView(job: SerialJob): Record<string, unknown> {
    const op = job.operation !== null ? this.streamer.ops.get(job.operation) : undefined;
    return jobView(job, op, this.streamer.position(job));
  }

  private putJob(job: SerialJob, body: unknown): Response {
    const s = this.streamer;
    if (!isRecord(body)) throw new G2Fail(101, 'expected {"state":…} or {"position":…}');
    if (typeof body.position === 'number') s.moveJob(job, body.position);
    else {
      const op = job.operation !== null ? s.ops.get(job.operation) : undefined;
      if (body.state === 'run') {
        if (job.state === 'queued') s.startJob(job);
        else if (op && job.state === 'paused') s.resume(op);
        else throw new G2Fail(106, `job ${job.id} is ${job.state}`);
      } else if (body.state === 'pause') {
        if (!op || job.state !== 'running') throw new G2Fail(106, `job ${job.id} is ${job.state}`);
        s.pause(op);
      } else if (body.state === 'kill') {
        if (op && (job.state === 'running' || job.state === 'paused')) s.kill(op);
        else if (job.state === 'queued') s.killQueued(job);
        else throw new G2Fail(106, `job ${job.id} is ${job.state}`);
      } else throw new G2Fail(101, 'state must be "run", "pause" or "kill"');
    }
    return jsonResponse(this.jobView(job));
  }
}

function isJson(v: unknown, depth = 0): v is Json {
  if (depth > 4) return false;
  if (v === null || typeof v === 'boolean' || typeof v === 'string') return true;
  if (typeof v === 'number') return Number.isFinite(v);
  if (Array.isArray(v)) return v.every((x) => isJson(x, depth + 1));
  if (typeof v === 'object') return Object.values(v).every((x) => isJson(x, depth + 1));
  return false;
}
