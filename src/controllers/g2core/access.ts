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
 * Who may send which g2core REST request (enforced by the gateway, mirrored by the UI).
 *
 *  viewer      every GET that only reads (version, status reports, machine tree, operations, jobs)
 *  operator    job controls: pause / resume / kill operations and jobs, queue and start jobs,
 *              upload job files of plain G-code (`operatorJobLineProblem`: motion, spindle,
 *              coolant, tool change, program stops; no `$` settings, no JSON, no G10/M100…); alarm clear (`GET /machine/clear`, a GET that is a command);
 *              jog and home (POST /operation whose lines are all jog or G28.2 lines, see
 *              `isJogOrHomeLine`: operators stand at the machine); feed/spindle overrides
 *              (`PUT /machine/mfo|mto|sso` with a number)
 *  supervisor  settings (`PUT /machine/…`), jobs with any other line (the refusal names it), the G-code console (any other POST /operation),
 *              triggering alarm/shutdown/panic (`GET /machine/alarm|shutd|panic`), deleting jobs,
 *              the hard reset of a serial board (`POST /board/reset`, src/controllers/g2core/server/),
 *              anything undeclared that is not a GET, WebSocket upgrades (g2core has none).
 *
 * Keys are classified in their canonical form (`canonicalKey`): `/machine/sys/clear`,
 * `/machine/sys.clear`, `/machine/SYS/CLEAR` and `/machine/clear` are the same command. The
 * firmware reads `{"clear":null}` as a command wherever it appears, so a `filter` that names a
 * command key is that command, and a GET with a body (the design reads filters, and in one
 * example a value, from a GET body) is not a read.
 *
 * POST /operation, PUT of an override and every GET are classified with their body:
 * `g2coreAccessNeedsBody` asks the gateway to read it.
 */

/** Override keys an operator may set while a job runs (sys group). */
export const OVERRIDE_KEYS = ['mfo', 'mto', 'sso'] as const;

/** Keys whose GET is a command in the firmware (`config_app.cpp`: cm_clr, cm_alrm, cm_shutd, cm_pnic). */
const COMMAND_KEYS: Record<string, 'operator' | 'supervisor'> = {
  clear: 'operator',
  clr: 'operator',
  alarm: 'supervisor',
  shutd: 'supervisor',
  panic: 'supervisor',
};

/** Keys that carry G-code (`{"gc":"G0 X1"}` runs it): never in a filter. */
const GCODE_KEYS = new Set(['gc', 'gc2']);

/** The parts of a key: whitespace and control characters dropped, lower case, split at `/` and `.`. */
function keyParts(raw: string): string[] {
  const parts = raw
    // eslint-disable-next-line no-control-regex
    .replace(/[\s\u0000-\u001f\u007f-\u009f]/g, '')
    .toLowerCase()
    .split(/[/.]/)
    .filter((p) => p !== '');
  while (parts.length > 1 && parts[0] === 'sys') parts.shift();
  return parts;
}

/**
 * The one form of a key: `sys/MFO`, `sys.mfo`, ` mfo `, `sysmfo` → `mfo`; `x/vm`, `x.vm` → `xvm`.
 * The `sys` group prefix is dropped (system keys are freestanding in the firmware).
 */
export function canonicalKey(raw: string): string {
  let flat = keyParts(raw).join('');
  while (flat.startsWith('sys') && flat.length > 3) flat = flat.slice(3);
  return flat;
}

/** The command a key names, looking at its canonical form and at each of its parts. */
function commandOf(raw: string): 'operator' | 'supervisor' | null {
  const names = [canonicalKey(raw), ...keyParts(raw)];
  let found: 'operator' | 'supervisor' | null = null;
  for (const n of names) {
    const c = COMMAND_KEYS[n];
    if (c === 'supervisor') return c;
    if (c) found = c;
  }
  return found;
}

function commandDecision(role: 'operator' | 'supervisor', what: string): AccessDecision {
  return role === 'operator' ? operator('clear alarm') : supervisor(`trigger ${what}`);
}

/** Percent-decodes until nothing changes (a server may decode more than once). Null if invalid. */
function decodeAll(s: string): string | null {
  let cur = s;
  for (let k = 0; k < 4; k++) {
    let next: string;
    try {
      next = decodeURIComponent(cur);
    } catch {
      return null;
    }
    if (next === cur) return cur;
    cur = next;
  }
  return cur;
}

interface Target {
  /** Lower-cased route segments, decoded once, empty ones dropped (`/Machine//x/` → machine, x). */
  segs: string[];
  /** `/machine/{key}`: the key as decoded once (null when not valid percent-encoding). */
  key: string | null;
  /** The key segments, still encoded. */
  rawKey: string;
}

function target(path: string): Target {
  const raw = (path.split('?')[0] ?? '').split('/').filter((s) => s !== '');
  const segs: string[] = [];
  for (const s of raw) {
    try {
      segs.push(decodeURIComponent(s).toLowerCase());
    } catch {
      segs.push(s.toLowerCase());
    }
  }
  const rawKey = raw.slice(1).join('/');
  let key: string | null;
  try {
    key = decodeURIComponent(rawKey);
  } catch {
    key = null;
  }
  return { segs, key, rawKey };
}

/** The strongest command a filter names (keys at any depth), or why it cannot be read. */
function filterCommand(text: string): AccessDecision | null {
  let spec: unknown;
  try {
    spec = JSON.parse(text);
  } catch {
    return supervisor("read with a filter that is not JSON (the firmware's relaxed JSON may name a command)");
  }
  let found: AccessDecision | null = null;
  const walk = (v: unknown): AccessDecision | null => {
    if (Array.isArray(v)) {
      for (const x of v) {
        const d = walk(x);
        if (d?.role === 'supervisor') return d;
      }
      return null;
    }
    if (typeof v !== 'object' || v === null) return null;
    for (const [k, inner] of Object.entries(v)) {
      if (GCODE_KEYS.has(canonicalKey(k))) return supervisor('read with a filter that carries G-code');
      const c = commandOf(k);
      if (c === 'supervisor') return commandDecision(c, canonicalKey(k));
      if (c) found = commandDecision(c, canonicalKey(k));
      const d = walk(inner);
      if (d?.role === 'supervisor') return d;
    }
    return null;
  };
  return walk(spec) ?? found;
}

function getDecision(t: Target, query: URLSearchParams, body: string | undefined): AccessDecision {
  if (body !== undefined && body.trim() !== '')
    return supervisor('a GET with a body (the design reads filters and values from it)');
  let strongest: AccessDecision | null = null;
  for (const [k, v] of query) {
    if (k.trim().toLowerCase() !== 'filter') continue;
    const d = filterCommand(v);
    if (d?.role === 'supervisor') return d;
    strongest ??= d;
  }
  if (t.segs[0] === 'machine' && t.segs.length > 1) {
    const key = decodeAll(t.rawKey);
    if (key === null) return supervisor('read a key that is not valid percent-encoding');
    const c = commandOf(key);
    if (c) return commandDecision(c, canonicalKey(key));
  }
  return strongest ?? read();
}

const JSON_WS = '[ \\t\\r\\n]*';
const JSON_NUMBER = '-?(?:0|[1-9]\\d*)(?:\\.\\d+)?(?:[eE][-+]?\\d+)?';
const BARE_NUMBER = new RegExp(`^${JSON_WS}${JSON_NUMBER}${JSON_WS}$`);
const KEYED_NUMBER = new RegExp(
  `^${JSON_WS}\\{${JSON_WS}"([A-Za-z./]+)"${JSON_WS}:${JSON_WS}${JSON_NUMBER}${JSON_WS}\\}${JSON_WS}$`,
);

/** The override a `PUT /machine/{key}` addresses: only from a key that needs no second decoding. */
function overrideKey(t: Target): string | null {
  if (t.segs[0] !== 'machine' || t.segs.length < 2 || t.key === null || t.key.includes('%')) return null;
  const k = canonicalKey(t.key);
  return (OVERRIDE_KEYS as readonly string[]).includes(k) ? k : null;
}

/** An override is a number, bare or as `{"<the same key>": number}`; anything else is a setting. */
function overrideDecision(key: string, body: string | undefined): AccessDecision {
  const b = body ?? '';
  const keyed = KEYED_NUMBER.exec(b);
  if (BARE_NUMBER.test(b) || (keyed && canonicalKey(keyed[1] ?? '') === key))
    return operator('change feed/spindle override');
  return supervisor('change a setting (an override body other than a number)');
}

const AXIS_WORD = '[XYZABC][-+]?(?:\\d+\\.?\\d*|\\.\\d+)';
const NUM = '(?:\\d+\\.?\\d*|\\.\\d+)';
const JOG_LINE = new RegExp(`^G91\\s*G[01](?:\\s*${AXIS_WORD})+(?:\\s*F${NUM})?$`, 'i');
const HOME_LINE = new RegExp(`^G28\\.2(?:\\s*[XYZABC]0)+$`, 'i');
const RESTORE_LINE = /^G90$/i;

/** True for the only lines an operator's operation may contain: relative jogs, G90, G28.2 homing. */
export function isJogOrHomeLine(line: string): boolean {
  const l = line.trim();
  return JOG_LINE.test(l) || HOME_LINE.test(l) || RESTORE_LINE.test(l);
}

/**
 * True when a JSON text repeats a key in one object (compared lower-cased and trimmed): a parser
 * that keeps the first copy would read something else than `JSON.parse`, which keeps the last.
 * The text must already be valid JSON.
 */
function repeatsKeys(text: string): boolean {
  const stack: Array<Set<string> | null> = [];
  let prev = '';
  for (let i = 0; i < text.length; i++) {
    const c = text[i] ?? '';
    if (c === '"') {
      let j = i + 1;
      while (j < text.length && text[j] !== '"') j += text[j] === '\\' ? 2 : 1;
      const top = stack[stack.length - 1];
      if (top && (prev === '{' || prev === ',')) {
        const k = (JSON.parse(text.slice(i, j + 1)) as string).trim().toLowerCase();
        if (top.has(k)) return true;
        top.add(k);
      }
      i = j;
      prev = '"';
      continue;
    }
    if (c === '{') stack.push(new Set());
    else if (c === '[') stack.push(null);
    else if (c === '}' || c === ']') stack.pop();
    if (!/\s/.test(c)) prev = c;
  }
  return false;
}

function operationDecision(body: string | undefined): AccessDecision {
  const console = supervisor('run G-code (console)');
  if (!body) return console;
  let parsed: unknown;
  try {
    parsed = JSON.parse(body);
  } catch {
    return console;
  }
  if (typeof parsed !== 'object' || parsed === null || Array.isArray(parsed)) return console;
  if (repeatsKeys(body) || !Object.keys(parsed).every((k) => k === 'optype' || k === 'value')) return console;
  const { optype, value } = parsed as { optype?: unknown; value?: unknown };
  if (optype === 'sendfile') return operator('run a job file');
  if (optype !== 'run') return console;
  const lines = Array.isArray(value)
    ? value
    : typeof value === 'string'
      ? value.split(/\r?\n/).filter((l) => l.trim() !== '')
      : null;
  if (!lines || lines.length === 0 || !lines.every((l) => typeof l === 'string' && isJogOrHomeLine(l)))
    return console;
  return (lines as string[]).some((l) => /G28\.2/i.test(l)) ? operator('home axes') : operator('jog');
}

// ------------------------------------------------------------------ an operator's job

/**
 * G and M codes an operator's job may hold: motion, dwell, planes, units, the work offsets in
 * use (not stored ones), going to the stored positions, probing, path and distance modes, the
 * spindle, coolant, tool change and program stops. Not: `G10` and `G28.1`/`G30.1` (they write
 * offsets and positions the board keeps), `G28.3` (sets the machine position), `M48`–`M51`
 * (override enables), `M100`/`M101` (JSON inside G-code), and any code not named here.
 */
const JOB_G = new Set(
  '0 1 2 3 4 17 18 19 20 21 28 28.2 30 38.2 38.3 38.4 38.5 40 49 53 54 55 56 57 58 59 59.1 59.2 59.3 61 61.1 64 80 90 90.1 91 91.1 92 92.1 92.2 92.3 93 94'.split(
    ' ',
  ),
);
const JOB_M = new Set('0 1 2 3 4 5 6 7 8 9 30 60'.split(' '));
/** The longest job line an operator's job may hold (the firmware's line buffer is 254 bytes). */
const MAX_JOB_LINE = 255;
/** Word letters besides G and M: axes, arc centres and radius, feed, speed, tool, dwell, line numbers. */
const JOB_WORDS = new Set('ABCFIJKNPRSTUVWXYZ'.split(''));

/**
 * Why a line of a job needs a supervisor, or null when an operator's job may hold it: plain
 * G-code only, in printable ASCII. Settings writes (`$…`), JSON (`{…}`), text-mode commands
 * (`?`, `H`), single-character controls and any code outside the lists above need a supervisor.
 * A line is judged as the controller would read it (a comment is allowed, its text is not run).
 */
export function operatorJobLineProblem(line: string): string | null {
  if (/[^\t\x20-\x7e]/.test(line)) return 'a character outside printable ASCII';
  // The firmware reads at most 254 bytes a line; the patterns below run on short lines only.
  if (line.length > MAX_JOB_LINE) return `a line longer than ${MAX_JOB_LINE} characters`;
  const t = line.trim();
  if (t === '' || t === '%') return null;
  if (t.startsWith('$')) return 'a settings write or text-mode command ($)';
  if (t.startsWith('{')) return 'a JSON command ({…})';
  if (/^[?!~%]/.test(t)) return `a control or text-mode command (${t[0] ?? ''})`;
  let code = t.replace(/\([^()]*\)/g, ' ');
  if (/[()]/.test(code)) return 'an unbalanced or nested comment';
  code = code.replace(/;.*$/, '').replace(/[ \t]/g, '').toUpperCase();
  const words = /^(?:[A-Z][-+]?(?:\d+(?:\.\d*)?|\.\d+))*$/.test(code)
    ? [...code.matchAll(/([A-Z])([-+]?(?:\d+(?:\.\d*)?|\.\d+))/g)]
    : null;
  if (!words) return 'not plain G-code';
  for (const [, letter = '', num = ''] of words) {
    if (letter === 'G' || letter === 'M') {
      const n = String(Number(num));
      if (!(letter === 'G' ? JOB_G : JOB_M).has(n)) return `${letter}${n}, not plain motion`;
    } else if (!JOB_WORDS.has(letter)) return `the word ${letter}, not plain motion`;
  }
  return null;
}

/** The first line of a job an operator may not queue, with its number, or null. */
function jobTextDecision(text: string): AccessDecision {
  const lines = text.split(/\r\n|\r|\n/);
  for (let i = 0; i < lines.length; i++) {
    const why = operatorJobLineProblem(lines[i] ?? '');
    if (why)
      return supervisor(
        `queue a job whose line ${i + 1} ${JSON.stringify((lines[i] ?? '').trim().slice(0, 60))} is ${why} (an operator's job holds plain G-code only)`,
      );
  }
  return operator('queue a job (upload)');
}

/**
 * The job file of a `multipart/form-data` upload, or null when the upload is not in the plain
 * form every parser reads alike: one boundary parameter, no preamble or epilogue, parts with only
 * Content-Disposition (form-data, quoted name and filename) and Content-Type headers, exactly one
 * `file` part and at most one `name` part. Anything else is not classified (a supervisor's).
 */
function multipartJobFile(contentType: string, body: string): string | null {
  const m = /^multipart\/form-data\s*;\s*boundary=("?)([0-9A-Za-z'()+_,\-./:=?]{1,70})\1\s*$/i.exec(
    contentType.trim(),
  );
  const b = m?.[2];
  if (!b) return null;
  const delim = `--${b}`;
  if (!body.startsWith(`${delim}\r\n`)) return null;
  const segs = body.slice(delim.length).split(`\r\n${delim}`);
  const last = segs.pop();
  if (last !== '--' && last !== '--\r\n') return null;
  const seen = new Map<string, string>();
  for (const seg of segs) {
    if (!seg.startsWith('\r\n')) return null;
    const at = seg.indexOf('\r\n\r\n', 2);
    if (at < 0) return null;
    const headers = seg.slice(2, at).split('\r\n');
    const content = seg.slice(at + 4);
    let name: string | null = null;
    const names = new Set<string>();
    for (const h of headers) {
      const hm = /^([A-Za-z-]+):[ \t]*(.*)$/.exec(h);
      const hn = hm?.[1]?.toLowerCase();
      if (!hm || !hn || names.has(hn)) return null;
      names.add(hn);
      if (hn === 'content-disposition') {
        const d = /^form-data((?:;[ \t]*(?:name|filename)="[^"\\\r\n]*")+)[ \t]*$/i.exec(hm[2] ?? '');
        if (!d) return null;
        const params = [...(d[1] ?? '').matchAll(/(name|filename)="([^"]*)"/gi)].map((x) => [
          (x[1] ?? '').toLowerCase(),
          x[2] ?? '',
        ]);
        if (new Set(params.map((x) => x[0])).size !== params.length) return null;
        name = params.find((x) => x[0] === 'name')?.[1] ?? null;
      } else if (hn !== 'content-type') return null;
    }
    if ((name !== 'file' && name !== 'name') || seen.has(name)) return null;
    seen.set(name, content);
  }
  return seen.get('file') ?? null;
}

/**
 * `POST /job`, classified by its content: an operator may queue a job of plain G-code
 * (`operatorJobLineProblem`); a job with any other line (a setting `$defa=1`, JSON `{"xsn":0}`,
 * `G10`, `M100`…) is a supervisor's, the refusal naming the line. The body is JSON
 * `{"name","gcode"}` or a plain multipart upload; a body in any other form is a supervisor's.
 */
function jobDecision(body: string | undefined, contentType: string | undefined): AccessDecision {
  const odd = supervisor(
    'queue a job whose upload is not plain JSON {"name","gcode"} or a plain multipart file',
  );
  if (!body) return odd;
  if ((contentType ?? '').toLowerCase().includes('multipart/')) {
    const file = multipartJobFile(contentType ?? '', body);
    return file === null ? odd : jobTextDecision(file);
  }
  let parsed: unknown;
  try {
    parsed = JSON.parse(body);
  } catch {
    return odd;
  }
  if (typeof parsed !== 'object' || parsed === null || Array.isArray(parsed) || repeatsKeys(body)) return odd;
  if (!Object.keys(parsed).every((k) => k === 'name' || k === 'gcode')) return odd;
  const { gcode } = parsed as { gcode?: unknown };
  return typeof gcode === 'string' ? jobTextDecision(gcode) : odd;
}

/** The most a `POST /job` body may be for the gateway to read it (a job of 8 MiB, multipart's headers). */
export const MAX_JOB_UPLOAD = 8 * 1024 * 1024 + 64 * 1024;

/** `{"opstate": "pause"}` / `{"state": "run"}`: which console command a control body is (the audit's commandId). */
function controlId(body: string | undefined, key: 'opstate' | 'state'): string | undefined {
  let v: unknown;
  try {
    v = body ? (JSON.parse(body) as unknown) : undefined;
  } catch {
    return undefined;
  }
  if (typeof v !== 'object' || v === null || Array.isArray(v) || repeatsKeys(body ?? '')) return undefined;
  const what = (v as Record<string, unknown>)[key];
  if (what === 'pause') return 'g2core.feedhold';
  if (what === 'kill') return 'g2core.kill';
  // A job's run starts it (a held job's resume reads the same: the board knows which it is).
  if (what === 'run') return key === 'state' ? 'g2core.run-job' : 'g2core.resume';
  return undefined;
}

export const g2coreAccess: AccessPolicy = (req) => {
  const m = req.method.toUpperCase();
  if (req.websocket) return supervisor('open a WebSocket (g2core has none: the server would see a GET)');
  const t = target(req.path);
  const [top, id] = t.segs;
  const n = t.segs.length;

  if (m === 'GET' || m === 'HEAD') return getDecision(t, req.query, req.body);

  if (m === 'PUT' && top === 'machine' && n >= 2) {
    const k = overrideKey(t);
    return k ? overrideDecision(k, req.body) : supervisor('change a setting');
  }
  if (m === 'POST' && top === 'operation' && n === 1) return operationDecision(req.body);
  if (m === 'PUT' && top === 'operation' && n === 2 && id)
    return operator('pause, resume or kill an operation', controlId(req.body, 'opstate'));
  if (m === 'POST' && top === 'job' && n === 1) return jobDecision(req.body, req.contentType);
  if (m === 'PUT' && top === 'job' && n === 2 && id)
    return operator('start, pause, kill or reorder a job', controlId(req.body, 'state'));
  if (m === 'DELETE' && top === 'job' && n === 2 && id) return supervisor('delete a job');
  // A serial board's hard reset (^X), served by the gateway's bridge (src/controllers/g2core/server/).
  if (m === 'POST' && top === 'board' && n === 2 && id === 'reset')
    return supervisor('reset the board (^X): a serial board stuck in run');
  return defaultDecision(req);
};

/**
 * The gateway reads the body of: POST /operation (jog/home or console), POST /job (an operator's
 * job holds plain G-code only; up to `MAX_JOB_UPLOAD`, see `g2coreAccessBodyLimit`), a PUT of an
 * override (a number, or something more), a PUT controlling an operation or a job (which command it
 * is: the audit's commandId), and every GET ('viewer': a GET with a body is not a read).
 */
export const g2coreAccessNeedsBody: BodyNeeded = (method, path) => {
  const m = method.toUpperCase();
  if (m === 'GET' || m === 'HEAD') return 'viewer';
  const t = target(path);
  if (m === 'POST') return t.segs.length === 1 && (t.segs[0] === 'operation' || t.segs[0] === 'job');
  // Operation and job controls: read to know which command they are (the audit's commandId).
  if (m === 'PUT')
    return (
      overrideKey(t) !== null ||
      (t.segs.length === 2 && (t.segs[0] === 'operation' || t.segs[0] === 'job') && !!t.segs[1])
    );
  return false;
};

/** How much of a body the gateway reads to classify it: a whole job for `POST /job`. */
export const g2coreAccessBodyLimit = (method: string, path: string): number | undefined => {
  const t = target(path);
  return method.toUpperCase() === 'POST' && t.segs.length === 1 && t.segs[0] === 'job'
    ? MAX_JOB_UPLOAD
    : undefined;
};
