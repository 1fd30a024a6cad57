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
import { cloneJson, diffModel, isObject, type Json, type JsonObject } from '../patch';
import { baseModel, EMPTY_JOB_FILE } from './data/model';
import { iso, MemFs, normalize, seedFiles } from './files';

/**
 * A simulated Duet in SBC mode (DSF 3.5), speaking the REST + WebSocket API of
 * `duet-dsf-rest-api.txt`. Everything here is simulated (the app says so).
 *
 * - Sessions: `GET /machine/connect` gives a session key; a session lives 8 s after its last
 *   request unless a socket is open, then requests with its key get 403 (the document's words).
 *   A request without a key is accepted only when no password is set ("If no password is expected,
 *   the password key can be omitted"); a key that is unknown or expired is always refused.
 * - `WS /machine?sessionKey=`: the full model first, then patches made by diffing the model against
 *   what this client last received. Nothing is sent until the client answered `OK\n`; changes made
 *   meanwhile are coalesced into the next patch (that is what diffing gives). `PING\n` → `PONG\n`.
 *   A refused socket is closed with 1008 (DSF answers the upgrade with HTTP 403, which a browser
 *   only sees as a failed socket).
 * - Time passes every `tickMs`: heaters warm, a print advances `job.filePosition`, layers, axes.
 */

export interface DuetSimOptions extends SimOptions {
  /** DSF password; null/undefined: no password protection. */
  password?: string | null;
  /** Session lifetime without socket or request (ms); the document says at least 8 s. */
  sessionTimeoutMs?: number;
}

interface SockState {
  sock: SimSocket;
  key: string | null;
  sent: JsonObject;
  awaitingOk: boolean;
  pending: Json[];
  userSessionId: number;
}

interface Session {
  lastSeen: number;
  sockets: number;
}

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

function o(v: Json | undefined): JsonObject {
  if (!isObject(v)) throw new Error('simulator model: object expected');
  return v;
}
function arr(v: Json | undefined): Json[] {
  return Array.isArray(v) ? v : [];
}

/** Value of a G-code parameter: `P"text"` (quotes removed, "" unescaped), `S12`, `R{...}`. */
export function gcodeParam(line: string, letter: string): string | null {
  const re = new RegExp(`\\s${letter}("(?:[^"]|"")*"|\\{[^}]*\\}|[^\\s;]*)`, 'i');
  const m = re.exec(` ${line.replace(/^\s*[GMT]\d+(?:\.\d+)?/i, '')}`);
  if (!m) return null;
  const v = m[1] ?? '';
  if (v.startsWith('"')) return v.slice(1, -1).replace(/""/g, '"');
  return v;
}

export class DuetSimulator implements Simulator {
  readonly kind = 'duet' as const;
  model: JsonObject;
  readonly fs: MemFs;
  password: string | null;
  /** The last 500 answers received with M292, for tests and the developer panel. */
  readonly answers: MessageBoxAnswer[] = [];
  /** Codes received, for tests. */
  readonly codes: string[] = [];
  /** While frozen the sockets stay open but nothing is sent (no patches, no PONG): a dead link. */
  frozen = false;
  /** Refuse WebSocket upgrades (a proxy without WebSocket support): the console polls instead. */
  refuseSockets = false;
  /** HTTP requests received ("GET /machine/noop"), for tests. */
  readonly requests: string[] = [];
  /** PING frames received, for tests. */
  pings = 0;
  /** Told every `messages` event (the standalone simulator turns them into `rr_reply` text). */
  readonly messageListeners: Array<(type: 0 | 1 | 2, content: string) => void> = [];
  private readonly now: () => number;
  private readonly sessionTimeoutMs: number;
  private readonly sessions = new Map<string, Session>();
  private readonly sockets = new Set<SockState>();
  private timer: ReturnType<typeof setInterval> | null = null;
  private last: number;
  private job: RunningJob | null = null;
  private boxSeq = 0;
  private boxOpenedAt = 0;
  private startingUntil = 0;
  private phaseUntil = 0;
  private keySeq = 0;
  private userSessionSeq = 0;
  private pluginSeq = 0;
  /** Demo mode (control `demo`): the print to repeat, and when to start it next. */
  private demo: { path: string; nextAt: number } | null = null;

  constructor(opts: DuetSimOptions) {
    this.now = opts.now ?? Date.now;
    this.password = opts.password ?? null;
    this.sessionTimeoutMs = opts.sessionTimeoutMs ?? 8000;
    this.model = baseModel(opts.name);
    this.fs = new MemFs(this.now);
    seedFiles(this.fs);
    this.last = this.now();
    const tick = opts.tickMs ?? 250;
    this.timer = setInterval(() => this.tick(), tick);
  }

  dispose(): void {
    if (this.timer) clearInterval(this.timer);
    this.timer = null;
    for (const s of [...this.sockets]) s.sock.close(1001, 'simulator disposed');
    this.sockets.clear();
  }

  // ------------------------------------------------------------------ model access

  private get state(): JsonObject {
    return o(this.model['state']);
  }
  private get jobObj(): JsonObject {
    return o(this.model['job']);
  }
  private heaters(): Array<JsonObject | null> {
    return arr(o(this.model['heat'])['heaters']).map((h) => (isObject(h) ? h : null));
  }
  private axes(): JsonObject[] {
    return arr(o(this.model['move'])['axes']).filter(isObject);
  }
  get status(): string {
    return String(this.state['status']);
  }
  private setStatus(s: string): void {
    this.state['status'] = s;
  }

  // ------------------------------------------------------------------ messages and sockets

  /** A `messages` event to every connected client (type 0 info, 1 warning, 2 error). */
  message(type: 0 | 1 | 2, content: string): void {
    const m: JsonObject = { content, time: new Date(this.now()).toISOString(), type };
    for (const s of this.sockets) s.pending.push(m);
    for (const l of this.messageListeners) l(type, content);
    this.flush();
  }

  /** Send each client that is not waiting for `OK` what changed since its last frame. */
  flush(): void {
    if (this.frozen) return;
    for (const s of this.sockets) {
      if (s.awaitingOk) continue;
      const d = diffModel(s.sent, this.model);
      if (!d && s.pending.length === 0) continue;
      const frame: JsonObject = { ...(d ?? {}) };
      if (s.pending.length) frame['messages'] = s.pending;
      s.pending = [];
      s.sent = cloneJson(this.model);
      s.awaitingOk = true;
      s.sock.send(JSON.stringify(frame));
    }
  }

  /** Number of frames a client has not acknowledged: 0 or 1 by construction. */
  get openSockets(): number {
    return this.sockets.size;
  }

  socket(path: string, sock: SimSocket): SimSocketHandler | null {
    const { pathname, query } = splitPath(path);
    if (pathname !== '/machine' || this.refuseSockets) return null;
    const key = query.get('sessionKey');
    const session = key ? this.liveSession(key) : null;
    if ((key && !session) || (!key && this.password)) {
      queueMicrotask(() => sock.close(1008, '403 Forbidden: invalid session key'));
      return { message: () => undefined, close: () => undefined };
    }
    if (session) session.sockets++;
    const userSessionId = ++this.userSessionSeq;
    const dsf = o(o(this.model['sbc'])['dsf']);
    dsf['userSessions'] = [
      ...arr(dsf['userSessions']),
      {
        accessLevel: 'readWrite',
        id: userSessionId,
        origin: '::ffff:192.0.2.200',
        originId: -1,
        sessionType: 'http',
      },
    ];
    const st: SockState = {
      sock,
      key,
      sent: cloneJson(this.model),
      awaitingOk: true,
      pending: [],
      userSessionId,
    };
    this.sockets.add(st);
    // First frame: the whole object model.
    sock.send(JSON.stringify({ ...this.model, messages: [] }));
    this.flush();
    return {
      message: (data) => {
        const text = data.trim();
        if (text === 'PING') this.pings++;
        if (this.frozen) return;
        if (text === 'OK') {
          st.awaitingOk = false;
          this.flush();
        } else if (text === 'PING') {
          sock.send('PONG\n');
        }
      },
      close: () => this.dropSocket(st),
    };
  }

  private dropSocket(st: SockState): void {
    if (!this.sockets.delete(st)) return;
    if (st.key) {
      const s = this.sessions.get(st.key);
      if (s) {
        s.sockets = Math.max(0, s.sockets - 1);
        s.lastSeen = this.now();
      }
    }
    const dsf = o(o(this.model['sbc'])['dsf']);
    dsf['userSessions'] = arr(dsf['userSessions']).filter(
      (u) => !(isObject(u) && u['id'] === st.userSessionId),
    );
    this.flush();
  }

  /** Close every socket with a code (1001 going away, 1011 server error: the DSF service died). */
  closeSockets(code: number, reason: string): void {
    for (const s of [...this.sockets]) {
      s.sock.close(code, reason);
      this.dropSocket(s);
    }
  }

  private liveSession(key: string): Session | null {
    const s = this.sessions.get(key);
    if (!s) return null;
    if (s.sockets === 0 && this.now() - s.lastSeen > this.sessionTimeoutMs) {
      this.sessions.delete(key);
      return null;
    }
    return s;
  }

  /** Forget every session (as if DSF restarted). */
  expireSessions(): void {
    this.sessions.clear();
  }

  // ------------------------------------------------------------------ HTTP

  async fetch(req: Request, path: string): Promise<Response> {
    const { pathname, query } = splitPath(path);
    const method = req.method.toUpperCase();
    this.requests.push(`${method} ${pathname}`);
    if (this.requests.length > 500) this.requests.splice(0, this.requests.length - 500);
    if (pathname === '/machine/connect' && method === 'GET') {
      if (this.password !== null && query.get('password') !== this.password)
        return new Response(null, { status: 403 });
      const key = `sim-${++this.keySeq}-${Math.random().toString(36).slice(2, 10)}`;
      this.sessions.set(key, { lastSeen: this.now(), sockets: 0 });
      return jsonResponse({ sessionKey: key });
    }
    const key = req.headers.get('X-Session-Key');
    if (key) {
      const s = this.liveSession(key);
      if (!s) return new Response(null, { status: 403 });
      s.lastSeen = this.now();
    } else if (this.password !== null) {
      return new Response(null, { status: 403 });
    }
    try {
      const res = await this.route(req, method, pathname, query, key);
      // Long requests (uploads, codes) keep the session alive until they finish.
      if (key) {
        const s = this.sessions.get(key);
        if (s) s.lastSeen = this.now();
      }
      return res;
    } finally {
      this.flush();
    }
  }

  private async route(
    req: Request,
    method: string,
    pathname: string,
    query: URLSearchParams,
    key: string | null,
  ): Promise<Response> {
    const fileArg = (prefix: string) => decodeURIComponent(pathname.slice(prefix.length));
    if (pathname === '/machine/noop' && method === 'GET') return new Response(null, { status: 204 });
    if (pathname === '/machine/disconnect' && method === 'GET') {
      if (key) this.sessions.delete(key);
      return new Response(null, { status: 204 });
    }
    if ((pathname === '/machine/status' || pathname === '/machine/model') && method === 'GET') {
      return jsonResponse({ ...this.model, messages: [] });
    }
    if (pathname === '/machine/code') {
      if (method !== 'POST') return new Response(null, { status: 405 });
      const body = await req.text();
      const reply = this.runCode(body);
      if (query.get('async') === 'true') {
        if (reply.trim())
          this.message(reply.startsWith('Error') ? 2 : reply.startsWith('Warning') ? 1 : 0, reply);
        return textResponse('');
      }
      return textResponse(reply);
    }
    if (pathname === '/machine/file/move' && method === 'POST') {
      const form = new URLSearchParams(await req.text());
      const from = form.get('from');
      const to = form.get('to');
      if (!from || !to) return textResponse('Missing from or to', 400);
      if (!this.fs.exists(from)) return textResponse(`File or directory ${from} not found`, 404);
      if (this.fs.exists(to)) {
        if (form.get('force') !== 'true') return textResponse(`Destination ${to} already exists`, 409);
        this.fs.remove(to, true);
      }
      this.fs.move(from, to);
      return new Response(null, { status: 204 });
    }
    if (pathname.startsWith('/machine/file/')) {
      const p = fileArg('/machine/file/');
      if (method === 'GET') {
        const f = this.fs.get(p);
        if (!f) return textResponse(`File ${p} not found`, 404);
        return new Response(f.data.slice().buffer, {
          status: 200,
          headers: { 'Content-Type': 'application/octet-stream' },
        });
      }
      if (method === 'PUT') {
        if (this.fs.isDir(p)) return textResponse(`${p} is a directory`, 500);
        const data = new Uint8Array(await req.arrayBuffer());
        const tm = query.get('timeModified');
        const modified = tm && !Number.isNaN(Date.parse(tm)) ? iso(Date.parse(tm)) : undefined;
        this.fs.write(p, data, modified);
        this.updateFreeSpace(-data.byteLength);
        return new Response(null, { status: 201 });
      }
      if (method === 'DELETE') {
        const r = this.fs.remove(p, query.get('recursive') === 'true');
        if (r === 'notFound') return textResponse(`File or directory ${p} not found`, 404);
        if (r === 'notEmpty') return textResponse(`Directory ${p} is not empty`, 500);
        return new Response(null, { status: 204 });
      }
    }
    if (pathname.startsWith('/machine/fileinfo/') && method === 'GET') {
      const p = fileArg('/machine/fileinfo/');
      const info = this.fs.fileInfo(p, query.get('readThumbnailContent') === 'true');
      if (!info) return textResponse(`File ${p} not found`, 404);
      return jsonResponse(info);
    }
    if (pathname.startsWith('/machine/directory/')) {
      const p = fileArg('/machine/directory/');
      if (method === 'GET') {
        const list = this.fs.list(p);
        if (!list) return textResponse(`Directory ${p} not found`, 404);
        return jsonResponse(list);
      }
      if (method === 'PUT') {
        this.fs.mkdirs(p);
        return new Response(null, { status: 201 });
      }
    }
    if (pathname === '/machine/plugin') return this.pluginRequest(req, method);
    if ((pathname === '/machine/startPlugin' || pathname === '/machine/stopPlugin') && method === 'POST') {
      const name = (await req.text()).trim();
      const plugin = o(this.model['plugins'])[name];
      if (!isObject(plugin)) return textResponse(`Plugin ${name} not found`, 500);
      if (pathname === '/machine/startPlugin') {
        if (plugin['sbcExecutable'] && Number(plugin['pid']) <= 0) plugin['pid'] = 1000 + ++this.pluginSeq;
      } else {
        plugin['pid'] = -1;
      }
      return new Response(null, { status: 204 });
    }
    return new Response(null, { status: 404 });
  }

  private async pluginRequest(req: Request, method: string): Promise<Response> {
    const plugins = o(this.model['plugins']);
    if (method === 'PUT') {
      const bytes = new Uint8Array(await req.arrayBuffer());
      if (bytes.length < 4 || bytes[0] !== 0x50 || bytes[1] !== 0x4b)
        return textResponse('Invalid plugin ZIP file', 500);
      // A stored (uncompressed) plugin.json is readable as it is; otherwise a numbered name.
      const latin = Array.from(bytes.subarray(0, 65536), (b) => String.fromCharCode(b)).join('');
      const id =
        /"id"\s*:\s*"([A-Za-z0-9_.-]{1,64})"/.exec(latin)?.[1] ?? `UploadedPlugin${++this.pluginSeq}`;
      const name = /"name"\s*:\s*"([^"]{1,80})"/.exec(latin)?.[1] ?? id;
      const version = /"version"\s*:\s*"([^"]{1,40})"/.exec(latin)?.[1] ?? '1.0.0';
      plugins[id] = {
        id,
        name,
        author: 'unknown',
        version,
        license: null,
        homepage: null,
        dwcFiles: [],
        dsfFiles: [],
        sdFiles: [],
        pid: -1,
        sbcRequired: false,
        sbcExecutable: null,
        sbcPermissions: [],
        tags: [],
        data: {},
      };
      this.message(0, `Plugin ${id} has been installed`);
      return new Response(null, { status: 204 });
    }
    if (method === 'DELETE') {
      const name = (await req.text()).trim();
      if (!(name in plugins)) return textResponse(`Plugin ${name} not found`, 500);
      delete plugins[name];
      return new Response(null, { status: 204 });
    }
    if (method === 'PATCH') {
      let body: unknown;
      try {
        body = JSON.parse(await req.text());
      } catch {
        return textResponse('Invalid JSON', 400);
      }
      if (!isObject(body as Json) || typeof (body as JsonObject)['plugin'] !== 'string')
        return textResponse('Invalid request', 400);
      const b = body as JsonObject;
      const p = plugins[String(b['plugin'])];
      if (!isObject(p)) return textResponse(`Plugin ${String(b['plugin'])} not found`, 500);
      const data = isObject(p['data']) ? p['data'] : (p['data'] = {});
      data[String(b['key'])] = b['value'] ?? null;
      return new Response(null, { status: 204 });
    }
    return new Response(null, { status: 405 });
  }

  private updateFreeSpace(delta: number): void {
    const v = arr(this.model['volumes'])[0];
    if (isObject(v) && typeof v['freeSpace'] === 'number')
      v['freeSpace'] = Math.max(0, v['freeSpace'] + delta);
  }

  // ------------------------------------------------------------------ G-code

  /** Run a body of codes; the reply text of all of them, joined by newlines. */
  runCode(body: string, depth = 0): string {
    const replies: string[] = [];
    for (const raw of body.split(/\r?\n/)) {
      const line = raw.replace(/;.*$/, '').trim();
      if (!line) continue;
      this.codes.push(line);
      if (this.codes.length > 500) this.codes.splice(0, this.codes.length - 500);
      const r = this.runLine(line, depth);
      if (r) replies.push(r);
    }
    this.flush();
    return replies.join('\n');
  }

  private runLine(line: string, depth: number): string {
    const m = /^([GMT])(\d+)(?:\.\d+)?/i.exec(line);
    if (!m) return `Error: Bad command: ${line}`;
    const word = `${(m[1] ?? '').toUpperCase()}${Number(m[2])}`;
    if (this.status === 'halted' && word !== 'M999' && word !== 'M112')
      return `Error: ${word}: the machine is halted (emergency stop); send M999 to reset it`;
    switch (word) {
      case 'M32':
        return this.startJob(
          line
            .replace(/^M32\s*/i, '')
            .replace(/^"(.*)"$/, '$1')
            .replace(/""/g, '"'),
          false,
        );
      case 'M37': {
        const p = gcodeParam(line, 'P');
        if (!p) return 'Error: M37: missing P parameter';
        return this.startJob(p, true);
      }
      case 'M25':
        if (this.status === 'processing' || this.status === 'simulating') {
          this.setStatus('pausing');
          this.phaseUntil = this.now() + 500;
          return '';
        }
        if (this.status === 'paused' || this.status === 'pausing') return '';
        return 'Error: M25: Cannot pause print, because no file is being printed!';
      case 'M24':
        if (this.status === 'paused') {
          this.setStatus('resuming');
          this.phaseUntil = this.now() + 500;
          return '';
        }
        if (this.job) return '';
        return 'Error: M24: Cannot print, because no file is selected!';
      case 'M0':
      case 'M1':
        if (this.status === 'paused' || this.status === 'pausing') {
          this.setStatus('cancelling');
          this.phaseUntil = this.now() + 500;
          return '';
        }
        if (this.job) return `Warning: ${word}: pause the print before cancelling it`;
        this.heatersOff();
        return '';
      case 'M112':
        this.emergencyStop();
        return '';
      case 'M999':
        this.reset();
        return '';
      case 'M292':
        return this.answerBox(line);
      case 'M291':
        this.raiseMessageBox(Number(gcodeParam(line, 'S') ?? '1'), {
          message: gcodeParam(line, 'P') ?? '',
          title: gcodeParam(line, 'R') ?? '',
          timeout: Number(gcodeParam(line, 'T') ?? '0'),
        });
        return '';
      case 'M98': {
        const p = gcodeParam(line, 'P');
        if (!p) return 'Error: M98: missing P parameter';
        const path = p.includes(':') || p.startsWith('/') ? p : `0:/macros/${p}`;
        const text = this.fs.text(path) ?? this.fs.text(`0:/sys/${p}`);
        if (text === null) return `Error: M98: Macro file ${p} not found`;
        if (depth > 8) return 'Error: M98: macro nesting too deep';
        return this.runCode(text, depth + 1);
      }
      case 'M562': {
        const p = gcodeParam(line, 'P');
        this.heaters().forEach((h, i) => {
          if (h && (p === null || Number(p) === i) && h['state'] === 'fault') h['state'] = 'off';
        });
        return '';
      }
      case 'G28': {
        for (const a of this.axes()) {
          a['homed'] = true;
          a['userPosition'] = 0;
          a['machinePosition'] = 0;
        }
        return '';
      }
      case 'G0':
      case 'G1': {
        const axes = this.axes();
        const moving = axes.filter((a) => gcodeParam(line, String(a['letter'])) !== null);
        if (moving.some((a) => !a['homed'])) return `Error: ${word}: insufficient axes homed`;
        for (const a of moving) {
          const v = Number(gcodeParam(line, String(a['letter'])));
          if (!Number.isNaN(v)) {
            a['userPosition'] = v;
            a['machinePosition'] = v;
          }
        }
        return '';
      }
      case 'G90':
      case 'G91':
      case 'M83':
      case 'M82':
      case 'M84':
      case 'M116':
        return '';
      case 'M104':
      case 'M109':
        this.setHeater(1, Number(gcodeParam(line, 'S') ?? '0'));
        return '';
      case 'M140':
      case 'M190':
        this.setHeater(0, Number(gcodeParam(line, 'S') ?? '0'));
        return '';
      case 'M141':
        this.setHeater(3, Number(gcodeParam(line, 'S') ?? '0'));
        return '';
      case 'M115': {
        const b = o(arr(this.model['boards'])[0]);
        return `FIRMWARE_NAME: ${String(b['firmwareName'])} FIRMWARE_VERSION: ${String(b['firmwareVersion'])} ELECTRONICS: ${String(b['name'])} FIRMWARE_DATE: ${String(b['firmwareDate'])}`;
      }
      default:
        return `Error: ${word}: Command is not supported`;
    }
  }

  private setHeater(i: number, temp: number): void {
    const h = this.heaters()[i];
    if (!h || Number.isNaN(temp)) return;
    h['active'] = temp;
    h['state'] = temp > 0 ? 'active' : 'off';
  }

  private setFan(i: number, v: number): void {
    const f = arr(this.model['fans'])[i];
    if (!isObject(f)) return;
    f['requestedValue'] = v;
    f['actualValue'] = v;
  }

  private heatersOff(): void {
    for (const h of this.heaters()) {
      if (!h) continue;
      h['active'] = 0;
      if (h['state'] !== 'fault') h['state'] = 'off';
    }
  }

  private startJob(rawPath: string, simulate: boolean): string {
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

  private emergencyStop(): void {
    if (this.job) this.finishJob('aborted');
    this.heatersOff();
    for (const a of this.axes()) a['homed'] = false;
    this.state['messageBox'] = null;
    this.setStatus('halted');
  }

  private reset(): void {
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

  private answerBox(line: string): string {
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

  // ------------------------------------------------------------------ developer panel

  controls(): SimControl[] {
    const boxes: SimControl[] = [0, 1, 2, 3, 4, 5, 6, 7].map((mode) => ({
      id: `box-${mode}`,
      label: `Message box: ${MODE_NAMES[mode] ?? mode}`,
      run: () => {
        this.raiseMessageBox(mode, mode === 2 ? { axisControls: 0b111 } : mode === 0 ? { timeout: 10 } : {});
      },
    }));
    return [
      { id: 'demo', label: 'Start a demo job', run: () => this.startDemo() },
      {
        id: 'heater-fault',
        label: 'Hotend heater fault (H1)',
        run: () => {
          const h = this.heaters()[1];
          if (h) h['state'] = 'fault';
          this.message(2, 'Heater 1 fault: temperature rising much more slowly than the expected 2.4°C/sec');
          this.flush();
        },
      },
      {
        id: 'dcs-down',
        label: 'DSF service restart (socket close 1011)',
        run: () => this.closeSockets(1011, 'DCS is unavailable'),
      },
      { id: 'expire-sessions', label: 'Expire all sessions', run: () => this.expireSessions() },
      {
        id: 'freeze',
        label: 'Freeze sockets (dead link) on/off',
        run: () => {
          this.frozen = !this.frozen;
          if (!this.frozen) this.flush();
        },
      },
      {
        id: 'no-socket',
        label: 'Refuse WebSockets (proxy without WebSocket) on/off',
        run: () => {
          this.refuseSockets = !this.refuseSockets;
          if (this.refuseSockets) this.closeSockets(1001, 'WebSocket not available');
        },
      },
      {
        id: 'warning',
        label: 'Controller warning message',
        run: () => this.message(1, 'Driver 0.3 warning: phase A may be disconnected'),
      },
      ...boxes,
    ];
  }
}

/** The demo print (on the seeded card) and the idle time between two runs. */
const DEMO_FILE = '0:/gcodes/bracket.gcode';
const DEMO_PAUSE_MS = 20_000;

const MODE_NAMES: Record<number, string> = {
  0: 'no buttons',
  1: 'close only',
  2: 'OK (+ jog)',
  3: 'OK / cancel',
  4: 'choices',
  5: 'integer',
  6: 'float',
  7: 'string',
};

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

export function createDuetSimulator(opts: SimOptions): Simulator {
  return new DuetSimulator(opts);
}
