import {
  jsonResponse,
  splitPath,
  textResponse,
  type SimControl,
  type SimOptions,
  type Simulator,
} from '../../../fleet/sim';
import { isObject, type Json, type JsonObject } from '../patch';
import { iso } from './files';
import { arr, o, type DuetSimOptions } from './link';
import { DuetSimMachine, gcodeParam } from './machine';

/**
 * A simulated Duet in SBC mode (DSF 3.5), speaking the REST + WebSocket API of
 * `duet-dsf-rest-api.txt`. Everything here is simulated (the app says so). Layers: link.ts (model,
 * sessions, sockets), machine.ts (heaters, jobs, message boxes, time, demo), this file (HTTP
 * routes, G-code, developer panel). Time passes every `tickMs`.
 */

export type { DuetSimOptions } from './link';
export { gcodeParam, type MessageBoxAnswer } from './machine';

export class DuetSimulator extends DuetSimMachine implements Simulator {
  readonly kind = 'duet' as const;
  private timer: ReturnType<typeof setInterval> | null = null;
  private pluginSeq = 0;

  constructor(opts: DuetSimOptions) {
    super(opts);
    const tick = opts.tickMs ?? 250;
    this.timer = setInterval(() => this.tick(), tick);
  }

  dispose(): void {
    if (this.timer) clearInterval(this.timer);
    this.timer = null;
    for (const s of [...this.sockets]) s.sock.close(1001, 'simulator disposed');
    this.sockets.clear();
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

export function createDuetSimulator(opts: SimOptions): Simulator {
  return new DuetSimulator(opts);
}
