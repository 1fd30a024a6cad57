import { jsonResponse, splitPath, textResponse, type SimOptions, type Simulator } from '../../../fleet/sim';
import { DEVICE } from './data/device';
import { GCODE_KEPT, XtoolSimMachine } from './machine';

/**
 * A simulated xTool D1 Pro (../shared/protocols/xtool-d-series-api.txt and the fixtures): no JSON
 * content type, strings until the first job, {"result":"fail"} with 200, unknown paths "no file",
 * uploads "ok" even when failed, frames with a terminator, WORK_STOPED, nothing on connect.
 * Layers: machine.ts (state, time, the physical world, the :8081 socket), this file (HTTP :8080).
 */

export {
  DEMO_JOB_LINES,
  DEMO_PRESS_MS,
  DEMO_REST_MS,
  FRAME_TERMINATOR,
  FRAMING_MS,
  GCODE_KEPT,
  LINES_PER_SECOND,
  STOP_MS,
  type SimMode,
} from './machine';

const JSON_NO_TYPE = null;
const ok = () => jsonResponse({ result: 'ok' }, 200, JSON_NO_TYPE);
const fail = () => jsonResponse({ result: 'fail' }, 200, JSON_NO_TYPE);
const noFile = () => jsonResponse({ result: 'no file' }, 200, JSON_NO_TYPE);
const answer = (body: unknown) => jsonResponse(body, 200, JSON_NO_TYPE);

export class XtoolSimulator extends XtoolSimMachine implements Simulator {
  readonly kind = 'xtool' as const;

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
