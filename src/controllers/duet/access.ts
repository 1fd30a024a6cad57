import {
  defaultDecision,
  operator,
  read,
  supervisor,
  type AccessDecision,
  type AccessPolicy,
  type BodyNeeded,
} from '../../fleet/access';

/**
 * Who may send which DSF request (the gateway enforces it, the UI hides or disables by it).
 *
 * - viewer: every GET (model, files, file info, directory listings), the socket, connect/noop/
 *   disconnect. No DSF GET changes the machine, so none is an audited command.
 * - operator: job control by G-code (see OPERATOR_CODES), uploading job files into `0:/gcodes/`.
 * - supervisor: any other G-code (console, macros, heater fault reset), other uploads (system,
 *   macros, filaments), deleting, moving, new folders, plugins.
 *
 * `POST /machine/code` is classified by the codes its body carries: every code in it must be an
 * operator code, else it needs a supervisor.
 */

/**
 * Decisions (the issue left them to us):
 * - M112 (emergency stop) is operator; M999 (board reset) is operator ONLY right after M112 in the
 *   same body — the emergency-stop sequence "M112\nM999" Duet Web Control sends. A bare M999
 *   resets the board in the middle of anything: supervisor.
 * - M292 (answer a message box) is operator: the firmware only accepts it while a box is open,
 *   and boxes are how a running job asks the person at the machine ("change filament, OK?").
 * - M32 (start) and M37 (simulate) are operator: starting a job file is job control.
 * - M0 (cancel), M25 (pause), M24 (resume) are operator.
 * - M562 (reset a heater fault) is supervisor: it re-arms a heater the firmware switched off
 *   for safety.
 * - M98 (run a macro) is supervisor: a macro is arbitrary G-code.
 */
const OPERATOR_CODES = new Set(['M0', 'M24', 'M25', 'M32', 'M37', 'M112', 'M292']);

/** Default job directory; uploads there are operator work. */
export const JOBS_DIR = '0:/gcodes/';

export interface CodeWord {
  /** "M112" (leading zeros dropped: M00 → M0) */
  word: string;
  line: number;
}

/**
 * The command words of a G-code body: one per line (RRF runs one command per line), comments
 * (`;…`, `(…)`) and quoted strings removed. A line whose first token is not a G/M/T word (meta
 * commands: if, while, var, set, echo, …) yields "META"; extra G/M/T words on a line are kept
 * so they are classified too.
 */
export function codeWords(body: string): CodeWord[] {
  const out: CodeWord[] = [];
  body.split(/\r?\n/).forEach((rawLine, line) => {
    const noStrings = rawLine.replace(/"(?:[^"]|"")*"/g, '""');
    const l = noStrings
      .replace(/;.*$/, '')
      .replace(/\([^)]*\)/g, '')
      .trim();
    if (!l) return;
    const stripped = l.replace(/^N\d+\s*/i, '');
    if (!/^[GMT]\d/i.test(stripped)) {
      out.push({ word: 'META', line });
      return;
    }
    for (const m of stripped.matchAll(/(?:^|[\s])([GMT])(\d+)(?:\.(\d+))?/gi)) {
      const letter = (m[1] ?? '').toUpperCase();
      const n = String(Number(m[2]));
      out.push({ word: `${letter}${n}${m[3] ? `.${m[3]}` : ''}`, line });
    }
  });
  return out;
}

export function classifyCode(body: string): AccessDecision {
  const words = codeWords(body);
  if (words.length === 0) return supervisor('send an empty G-code request');
  let afterEstop = false;
  for (const w of words) {
    if (w.word === 'M999' && afterEstop) continue;
    if (!OPERATOR_CODES.has(w.word))
      return supervisor(`send G-code ${w.word === 'META' ? '(meta command)' : w.word}`);
    if (w.word === 'M112') afterEstop = true;
  }
  const names = [...new Set(words.map((w) => w.word))].join(', ');
  return operator(`send ${names}`);
}

/** Default system directory (`directories.system`). */
export const SYSTEM_DIR = '0:/sys';

export function isSystemPath(p: string): boolean {
  const n = p.replace(/\/+/g, '/');
  return n === SYSTEM_DIR || n.startsWith(`${SYSTEM_DIR}/`) || n.split('/').includes('..');
}

function decodedPath(path: string, prefix: string): string {
  try {
    return decodeURIComponent(path.slice(prefix.length));
  } catch {
    return path.slice(prefix.length);
  }
}

export const duetAccess: AccessPolicy = (req) => {
  const path = req.path.split('?')[0] ?? req.path;
  const method = req.method.toUpperCase();
  if (req.websocket) return read('live object model');
  if (method === 'GET' || method === 'HEAD') {
    if (path === '/machine/connect') return read('connect');
    if (path === '/machine/disconnect') return read('disconnect');
    if (path.startsWith('/machine/file/')) {
      // config.g and friends can hold the machine password (M551) and WiFi keys (M587): system
      // files are for supervisors. Height maps (*.csv) stay readable for the height-map view.
      const target = decodedPath(path, '/machine/file/');
      if (isSystemPath(target) && !/\.csv$/i.test(target)) {
        return { role: 'supervisor', command: false, label: `read system file ${target}` };
      }
      return read('download a file');
    }
    return read();
  }
  if (method === 'POST' && path === '/machine/code') return classifyCode(req.body ?? '');
  if (method === 'PUT' && path.startsWith('/machine/file/')) {
    const target = decodedPath(path, '/machine/file/');
    const inJobs = target.startsWith(JOBS_DIR) && !target.slice(JOBS_DIR.length).split('/').includes('..');
    return inJobs ? operator(`upload job file ${target}`) : supervisor(`upload ${target}`);
  }
  if (method === 'DELETE' && path.startsWith('/machine/file/'))
    return supervisor(`delete ${decodedPath(path, '/machine/file/')}`);
  if (method === 'POST' && path === '/machine/file/move') return supervisor('move or rename a file');
  if (method === 'PUT' && path.startsWith('/machine/directory/'))
    return supervisor(`create folder ${decodedPath(path, '/machine/directory/')}`);
  if (path === '/machine/plugin') {
    if (method === 'PUT') return supervisor('install a plugin');
    if (method === 'DELETE') return supervisor('uninstall a plugin');
    if (method === 'PATCH') return supervisor('set plugin data');
  }
  if (method === 'POST' && path === '/machine/startPlugin') return supervisor('start a plugin');
  if (method === 'POST' && path === '/machine/stopPlugin') return supervisor('stop a plugin');
  return defaultDecision(req);
};

/** The gateway must read the body of `POST /machine/code` to classify it. */
export const duetAccessNeedsBody: BodyNeeded = (method, path) =>
  method.toUpperCase() === 'POST' && path.split('?')[0] === '/machine/code';
