import {
  operator,
  read,
  supervisor,
  type AccessDecision,
  type AccessPolicy,
  type AccessRequest,
  type BodyNeeded,
} from '../../fleet/access';

/**
 * Who may send which DSF request (the gateway enforces it, the UI hides or disables by it).
 *
 * Everything is an ALLOW-LIST: a request the rules below do not recognise for certain needs a
 * supervisor, GETs included (DSF answers GETs that run G-code, `rr_gcode`, delete files,
 * `rr_delete`, and plugins add their own GET endpoints).
 *
 * - viewer: the object model (`GET /machine/model|status`, `WS /machine`), connect/noop/
 *   disconnect, directory listings, and reading job files under `0:/gcodes/` (download, file info
 *   and thumbnails) and the height map `0:/sys/heightmap.csv`. No other file: config.g holds the
 *   machine password (M551) and WiFi keys (M587), macros and filaments may too.
 * - operator: job control by G-code (see `classifyCode`), uploading job files into `0:/gcodes/`.
 * - supervisor: any other G-code (console, macros, heater fault reset), reading any other file,
 *   other uploads, deleting, moving, new folders, plugins, system packages, the `rr_` API, plugin
 *   endpoints, and anything not listed here.
 *
 * Paths are classified in the form DSF resolves them (`normaliseDuetPath`): routes are matched
 * case-insensitively as ASP.NET does, the file name is decoded twice as DSF does
 * (`HttpUtility.UrlDecode` on a route value Kestrel already decoded), and the drive, backslashes,
 * `.` and `..` are resolved as `FilePath.ToPhysical` does.
 */

/** Default job directory; uploads there are operator work, its files are readable by viewers. */
export const JOBS_DIR = '0:/gcodes/';

/** The height map the height-map view reads (`move.compensation.file`, default). */
export const HEIGHT_MAP = '0:/sys/heightmap.csv';

// ------------------------------------------------------------------------------------ paths

/** C0 and C1 control characters: .NET's `(.*)` stops at a newline, RRF drops lines at 0x7F. */
// eslint-disable-next-line no-control-regex
const CONTROL = /[\u0000-\u001f\u007f-\u009f]/;

/**
 * A RepRapFirmware/FatFs path in the one form DSF resolves it to (`FilePath.ToPhysical`):
 * backslashes are separators; `<n>:` names a drive (any ASCII digits, so `00:` is `0:`), without
 * one the path is on drive 0 (relative to its root, a single leading `/` allowed); empty and `.`
 * segments are dropped and `..` resolved. Null when it cannot be classified for certain: control
 * characters, `..` above the drive root, an absolute host path (`//etc/…`), non-ASCII drive digits.
 * Case is kept: the allow-list compares exactly, so any other case is simply not allowed.
 */
export function normaliseDuetPath(raw: string): string | null {
  if (CONTROL.test(raw)) return null;
  const p = raw.replace(/\\/g, '/');
  let drive = 0;
  let rest: string;
  const m = /^(\d+):\/*(.*)$/.exec(p);
  if (m) {
    const digits = m[1] ?? '';
    if (digits.length > 9) return null; // int.TryParse fails: DSF would read a folder named "…:"
    drive = Number(digits);
    rest = m[2] ?? '';
  } else if (/^\p{Nd}+:/u.test(p)) {
    return null; // .NET's \d matches these digits, int.TryParse does not
  } else if (p.startsWith('/')) {
    rest = p.slice(1);
    if (rest.startsWith('/')) return null; // Path.Combine(base, "/etc/…") is the host's /etc
  } else {
    rest = p;
  }
  const out: string[] = [];
  for (const seg of rest.split('/')) {
    if (seg === '' || seg === '.') continue;
    if (seg === '..') {
      if (out.length === 0) return null;
      out.pop();
      continue;
    }
    out.push(seg);
  }
  return `${drive}:/${out.join('/')}`;
}

/** A file (not the folder itself) under `0:/gcodes/`. */
export function isJobFile(path: string): boolean {
  const n = normaliseDuetPath(path);
  return n !== null && n.startsWith(JOBS_DIR) && n.length > JOBS_DIR.length;
}

/** Files viewers and operators may read: job files and the height map. */
export function openToViewers(path: string): boolean {
  return isJobFile(path) || normaliseDuetPath(path) === HEIGHT_MAP;
}

/**
 * `HttpUtility.UrlDecode`: `+` is a space, `%XX` bytes are UTF-8, `%uXXXX` is a UTF-16 unit,
 * anything else (a lone `%`) stays as it is.
 */
function dotNetUrlDecode(s: string): string {
  let out = '';
  let bytes: number[] = [];
  const flush = () => {
    if (bytes.length > 0) out += new TextDecoder('utf-8').decode(new Uint8Array(bytes));
    bytes = [];
  };
  for (let i = 0; i < s.length; i++) {
    const c = s[i];
    if (c === '%' && /^u[0-9a-fA-F]{4}$/.test(s.slice(i + 1, i + 6))) {
      flush();
      out += String.fromCharCode(parseInt(s.slice(i + 2, i + 6), 16));
      i += 5;
    } else if (c === '%' && /^[0-9a-fA-F]{2}$/.test(s.slice(i + 1, i + 3))) {
      bytes.push(parseInt(s.slice(i + 1, i + 3), 16));
      i += 2;
    } else {
      flush();
      out += c === '+' ? ' ' : c;
    }
  }
  flush();
  return out;
}

interface Route {
  /** Route segments, decoded once (Kestrel) and lower-cased, without a trailing empty segment. */
  segs: string[];
  /** The raw (still percent-encoded) remainder after `skip` segments, as a catch-all sees it. */
  tail: (skip: number) => string;
}

/** Splits a path as ASP.NET routes it. Null when it is not valid percent-encoding. */
function route(path: string): Route | null {
  const raw = (path.split('?')[0] ?? '').split('/').filter((s, i) => i > 0 || s !== '');
  const trimmed = raw.length > 0 && raw[raw.length - 1] === '' ? raw.slice(0, -1) : raw;
  const segs: string[] = [];
  for (const s of trimmed) {
    if (s === '') continue;
    try {
      segs.push(decodeURIComponent(s).toLowerCase());
    } catch {
      return null;
    }
  }
  const nonEmpty = raw.filter((s) => s !== '');
  return { segs, tail: (skip) => nonEmpty.slice(skip).join('/') + (raw[raw.length - 1] === '' ? '/' : '') };
}

/**
 * The file a `{*filename}` route names, as DSF reads it: Kestrel decodes the path, then the
 * action decodes the value again with `HttpUtility.UrlDecode`. Null when it cannot be decoded.
 */
function routeFile(r: Route, skip: number): string | null {
  try {
    return dotNetUrlDecode(decodeURIComponent(r.tail(skip)));
  } catch {
    return null;
  }
}

/** A query parameter that could stand in for the route's file (model binding is case-insensitive). */
function namesAnotherFile(query: URLSearchParams): boolean {
  for (const k of query.keys()) if (/^(filename|directory|name|dir)$/i.test(k.trim())) return true;
  return false;
}

function fileRead(r: Route, query: URLSearchParams, what: 'download' | 'file info'): AccessDecision {
  const file = routeFile(r, 2);
  const label = `${what === 'download' ? 'read' : 'read file info of'} ${file ?? '(undecodable path)'}`;
  if (file === null || namesAnotherFile(query)) return supervisor(label);
  const ok = what === 'download' ? openToViewers(file) : isJobFile(file);
  // Reading another file changes nothing: a supervisor read, not an audited command.
  return ok ? read(label) : { role: 'supervisor', command: false, label };
}

function upload(r: Route, query: URLSearchParams): AccessDecision {
  const file = routeFile(r, 2);
  if (file === null || namesAnotherFile(query)) return supervisor(`upload ${file ?? '(undecodable path)'}`);
  return isJobFile(file)
    ? operator(`upload job file ${normaliseDuetPath(file)}`)
    : supervisor(`upload ${file}`);
}

function unknown(req: AccessRequest): AccessDecision {
  return supervisor(
    `${req.websocket ? 'WebSocket' : req.method.toUpperCase()} ${req.path} (not a DSF request the console makes: supervisor only)`,
  );
}

// ------------------------------------------------------------------------------------ rr_*

/**
 * A query parameter of an `rr_*` request, or null when it is absent or AMBIGUOUS: named more than
 * once (in any letter case), as RepRapFirmware and the gateway could then read different ones.
 */
function rrParam(query: URLSearchParams, name: string): string | null | 'ambiguous' {
  const values: string[] = [];
  for (const [k, v] of query) if (k.toLowerCase() === name) values.push(v);
  if (values.length > 1) return 'ambiguous';
  return values[0] ?? null;
}

/** Reading a file by `name`: job files (and the height map for downloads) are open to viewers. */
function rrFileRead(query: URLSearchParams, what: string, open: (file: string) => boolean): AccessDecision {
  const file = rrParam(query, 'name');
  if (file === 'ambiguous') return supervisor(`${what} (the file is named more than once)`);
  if (file === null) return read(`${what} of the job being printed`);
  const label = `${what} ${file}`;
  return open(file) ? read(label) : { role: 'supervisor', command: false, label };
}

/**
 * The standalone RepRapFirmware API (`rr_*`, all GET but `POST rr_upload`): the same rules as
 * the DSF requests they stand for. `rr_gcode?gcode=` carries its G-code in the query and is
 * classified exactly as the body of `POST /machine/code` (`classifyCode`); `rr_upload?name=` as
 * an upload, `rr_download`/`rr_fileinfo`/`rr_thumbnail?name=` as file reads; delete, move and new
 * folder are supervisor commands. A parameter given twice is not classified (supervisor).
 */
function rrAccess(req: AccessRequest, name: string): AccessDecision {
  const method = req.method.toUpperCase();
  const q = req.query;
  if (method === 'POST' && name === 'rr_upload') {
    const file = rrParam(q, 'name');
    if (file === null || file === 'ambiguous') return supervisor('upload a file (no single name)');
    return isJobFile(file)
      ? operator(`upload job file ${normaliseDuetPath(file)}`)
      : supervisor(`upload ${file}`);
  }
  if (method !== 'GET' && method !== 'HEAD') return unknown(req);
  switch (name) {
    case 'rr_connect':
      return read('connect');
    case 'rr_disconnect':
      return read('disconnect');
    case 'rr_model':
      return read('read the object model');
    case 'rr_reply':
      return read('read the G-code reply');
    case 'rr_upload':
      return read('read the last upload result');
    case 'rr_filelist':
    case 'rr_files': {
      const dir = rrParam(q, 'dir');
      return dir === 'ambiguous'
        ? supervisor('list a folder named more than once')
        : read(`list ${dir ?? ''}`);
    }
    case 'rr_download':
      return rrFileRead(q, 'read', openToViewers);
    case 'rr_fileinfo':
      return rrFileRead(q, 'read file info of', isJobFile);
    case 'rr_thumbnail':
      return rrFileRead(q, 'read a thumbnail of', isJobFile);
    case 'rr_gcode': {
      const gcode = rrParam(q, 'gcode');
      if (gcode === 'ambiguous') return supervisor('send G-code given more than once');
      return classifyCode(gcode ?? '');
    }
    case 'rr_delete':
      return supervisor(`delete ${String(rrParam(q, 'name') ?? '')}`);
    case 'rr_move':
      return supervisor('move or rename a file');
    case 'rr_mkdir':
      return supervisor(`create folder ${String(rrParam(q, 'dir') ?? '')}`);
    default:
      return unknown(req);
  }
}

export const duetAccess: AccessPolicy = (req) => {
  const r = route(req.path);
  if (!r) return supervisor(`${req.method} ${req.path} (not valid percent-encoding)`);
  const [top, a, b] = r.segs;
  const n = r.segs.length;
  if (!req.websocket && n === 1 && top?.startsWith('rr_')) return rrAccess(req, top);
  if (req.websocket) {
    return top === 'machine' && n === 1 ? read('live object model') : unknown(req);
  }
  if (top !== 'machine' || !a) return unknown(req);
  const method = req.method.toUpperCase();
  if (method === 'GET' || method === 'HEAD') {
    if (n === 2) {
      if (a === 'connect') return read('connect');
      if (a === 'disconnect') return read('disconnect');
      if (a === 'noop') return read('keep the session');
      if (a === 'model' || a === 'status') return read('read the object model');
    }
    if (a === 'file') return fileRead(r, req.query, 'download');
    if (a === 'fileinfo') return fileRead(r, req.query, 'file info');
    if (a === 'directory') {
      const dir = routeFile(r, 2);
      return dir === null ? supervisor('list an undecodable folder') : read(`list ${dir}`);
    }
    return unknown(req);
  }
  if (method === 'POST' && n === 2 && a === 'code') return classifyCode(req.body ?? '');
  if (method === 'PUT' && a === 'file') return upload(r, req.query);
  if (method === 'DELETE' && a === 'file') return supervisor(`delete ${routeFile(r, 2) ?? ''}`);
  if (method === 'POST' && n === 3 && a === 'file' && b === 'move')
    return supervisor('move or rename a file');
  if (method === 'PUT' && a === 'directory') return supervisor(`create folder ${routeFile(r, 2) ?? ''}`);
  if (n === 2 && a === 'plugin') {
    if (method === 'PUT') return supervisor('install a plugin');
    if (method === 'DELETE') return supervisor('uninstall a plugin');
    if (method === 'PATCH') return supervisor('set plugin data');
  }
  if (method === 'POST' && n === 2 && a === 'startplugin') return supervisor('start a plugin');
  if (method === 'POST' && n === 2 && a === 'stopplugin') return supervisor('stop a plugin');
  if (n === 2 && a === 'systempackage') return supervisor('install or remove a system package');
  return unknown(req);
};

/** The gateway must read the body of `POST /machine/code` to classify it (operator at least). */
export const duetAccessNeedsBody: BodyNeeded = (method, path) => {
  if (method.toUpperCase() !== 'POST') return false;
  const r = route(path);
  return r !== null && r.segs.length === 2 && r.segs[0] === 'machine' && r.segs[1] === 'code';
};

// ------------------------------------------------------------------------------------ G-code

/**
 * Decisions (the issue left them to us):
 * - M112 (emergency stop) is operator; M999 (board reset) is operator ONLY as the command right
 *   after M112 in the same body: the emergency-stop sequence "M112\nM999" Duet Web Control sends.
 *   A bare M999 resets the board in the middle of anything: supervisor.
 * - M292 (answer a message box) is operator: the firmware only accepts it while a box is open,
 *   and boxes are how a running job asks the person at the machine ("change filament, OK?").
 *   Only `P`, `S` (integers) and `R{<number>}` / `R{"<text>"}`, as the console sends them.
 * - M32 (start) and M37 (simulate) are operator for a file under `0:/gcodes/` named by an
 *   absolute quoted path (`M32 "0:/gcodes/a.gcode"`, `M37 P"…"`); any other file, an unquoted
 *   or relative name, or more parameters: supervisor.
 * - M0 (cancel), M25 (pause), M24 (resume) are operator, without parameters.
 * - M562 (reset a heater fault) is supervisor: it re-arms a heater the firmware switched off
 *   for safety.
 * - M98 (run a macro) is supervisor: a macro is arbitrary G-code.
 */

export interface GcodeParam {
  /** Upper-case parameter letter; null for the unprecedented string of M23/M28/M30/M32/M36/M117. */
  letter: string | null;
  kind: 'number' | 'string' | 'expression';
  /** The number as written, the string with `""` unescaped, or the expression with its braces. */
  text: string;
}

export interface GcodeCommand {
  /** "M112", "G28.2" (leading zeros dropped: M00 → M0) */
  word: string;
  params: GcodeParam[];
  /** 0-based line of the body. */
  line: number;
}

export type GcodeTokens =
  { ok: true; commands: GcodeCommand[] } | { ok: false; reason: string; line: number };

/** Codes whose parameter is the rest of the line (DSF `unprecedentedParameter`). */
const UNPRECEDENTED = new Set(['M23', 'M28', 'M30', 'M32', 'M36', 'M117']);
const NUMBER = /^[-+]?(?:\d+(?:\.\d*)?|\.\d+)/;

class Uncertain extends Error {}

/**
 * Splits a G-code body into commands the way RepRapFirmware (`StringParser`) and DSF's code parser
 * both read it, or refuses: wherever the two could read the text differently, or it holds anything
 * a job-control command would not, the result is `ok: false` and the body is not classified.
 *
 * Accepted: lines ending in LF or CRLF; leading spaces/tabs; `N<digits>` line numbers; commands
 * `G|M|T<digits>[.<digits>]` followed by a space, a tab, `;` or the line end; several commands on a
 * line separated by blanks; parameters `<letter><number>`, `<letter>"string"` (`""` is a quote),
 * `<letter>{expression}` (balanced, with quoted strings), each followed by a blank, `;` or the end;
 * `;` comments to the end of the line (not inside braces).
 *
 * Refused: a CR that is not before LF (RRF ends the line there, DSF drops it), control characters,
 * `(` `)` (comments in RRF's CNC mode and in DSF, text in RRF's FFF mode), `'` (RRF's lower-case
 * escape, inside strings too: `'.'.` reads `..`), `*` checksums, `:` and any other character, letters
 * glued to a code or value (`M25M98`: two commands to RRF, one to DSF), unbalanced quotes or braces,
 * `;` inside braces, quoted strings inside braces holding `{}()` (DSF does not skip strings there),
 * repeated parameters, unquoted file names, meta commands (if, while, var, set, echo, …).
 */
export function tokenizeGcode(body: string): GcodeTokens {
  const lines = body.split('\n');
  const commands: GcodeCommand[] = [];
  for (let li = 0; li < lines.length; li++) {
    let line = lines[li] ?? '';
    if (line.endsWith('\r')) line = line.slice(0, -1);
    try {
      commands.push(...tokenizeLine(line, li));
    } catch (e) {
      if (e instanceof Uncertain) return { ok: false, reason: e.message, line: li };
      throw e;
    }
  }
  return { ok: true, commands };
}

function tokenizeLine(line: string, li: number): GcodeCommand[] {
  if (CONTROL.test(line.replace(/\t/g, ' '))) throw new Uncertain('a control character');
  const out: GcodeCommand[] = [];
  let i = 0;
  const blank = (c: string | undefined) => c === ' ' || c === '\t';
  const skipBlanks = () => {
    while (blank(line[i])) i++;
  };
  /** After a code or value: a blank, a comment or the end of the line. */
  const mustEndToken = (what: string) => {
    const c = line[i];
    if (c !== undefined && !blank(c) && c !== ';') throw new Uncertain(`"${c}" right after ${what}`);
  };
  const atEnd = () => i >= line.length || line[i] === ';';

  skipBlanks();
  if (atEnd()) return out;
  const ln = /^[Nn]\d+/.exec(line.slice(i));
  if (ln) {
    i += ln[0].length;
    if (!blank(line[i])) throw new Uncertain('a line number not followed by a blank');
    skipBlanks();
    if (atEnd()) return out;
  }

  while (!atEnd()) {
    const code = /^([GgMmTt])(\d+)(?:\.(\d+))?/.exec(line.slice(i));
    if (!code) throw new Uncertain(`not a G/M/T command (meta command or unknown text) at column ${i + 1}`);
    const word = `${(code[1] ?? '').toUpperCase()}${Number(code[2])}${code[3] !== undefined ? `.${code[3]}` : ''}`;
    i += code[0].length;
    mustEndToken(word);
    const cmd: GcodeCommand = { word, params: [], line: li };
    out.push(cmd);
    const seen = new Set<string>();
    for (;;) {
      skipBlanks();
      if (atEnd()) break;
      const c = line[i] ?? '';
      if (UNPRECEDENTED.has(word)) {
        // DSF reads the rest of the line as the file name unless it is quoted; RRF stops at G/M.
        if (c !== '"') throw new Uncertain(`${word} takes one quoted file name`);
        cmd.params.push({ letter: null, kind: 'string', text: quoted() });
        mustEndToken(`the ${word} string`);
        skipBlanks();
        if (!atEnd()) throw new Uncertain(`text after the ${word} file name`);
        break;
      }
      // A G or M with a number starts the next command on the same line (RRF and DSF agree
      // once a blank separates them).
      if (/^[GgMm]\d/.test(line.slice(i, i + 2))) break;
      if (!/^[A-Za-z]$/.test(c)) throw new Uncertain(`"${c}" where a parameter letter belongs`);
      const letter = c.toUpperCase();
      if (seen.has(letter)) throw new Uncertain(`${word} repeats ${letter}`);
      seen.add(letter);
      i++;
      const v = line[i];
      if (v === '"') cmd.params.push({ letter, kind: 'string', text: quoted() });
      else if (v === '{') cmd.params.push({ letter, kind: 'expression', text: expression() });
      else {
        const num = NUMBER.exec(line.slice(i));
        if (!num) throw new Uncertain(`${letter} without a number, string or expression`);
        i += num[0].length;
        cmd.params.push({ letter, kind: 'number', text: num[0] });
      }
      mustEndToken(`${word} ${letter}`);
    }
  }
  return out;

  /** A double-quoted string at `i`; `""` is one quote. Leaves `i` after the closing quote. */
  function quoted(): string {
    let s = '';
    i++;
    for (;;) {
      const c = line[i];
      if (c === undefined) throw new Uncertain('an unterminated string');
      i++;
      if (c === '"') {
        if (line[i] === '"') {
          s += '"';
          i++;
          continue;
        }
        return s;
      }
      if (c === "'") throw new Uncertain("' in a string (RRF and DSF lower-case the next character)");
      s += c;
    }
  }

  /** A `{…}` expression at `i`, braces balanced, strings skipped as RRF skips them. */
  function expression(): string {
    const start = i;
    let depth = 0;
    for (;;) {
      const c = line[i];
      if (c === undefined) throw new Uncertain('an unterminated expression');
      if (c === '"') {
        const s = quoted();
        if (/[{}()]/.test(s))
          throw new Uncertain('a string holding {}() in an expression (DSF does not skip strings there)');
        continue;
      }
      if (c === ';') throw new Uncertain('; inside an expression');
      if (c === "'") throw new Uncertain("' inside an expression");
      i++;
      if (c === '{') depth++;
      if (c === '}' && --depth === 0) return line.slice(start, i);
    }
  }
}

const INTEGER = /^[-+]?\d+$/;
const R_NUMBER = /^\{[-+]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][-+]?\d+)?\}$/;
/** `{"text"}`: one string literal, nothing else (no `{}()'` inside; the tokenizer checked quotes). */
const R_STRING = /^\{"(?:[^"{}()']|"")*"\}$/;

/** Why a command is not operator work, or null when it is. */
function notOperator(cmd: GcodeCommand, previous: GcodeCommand | undefined): string | null {
  const only = (...letters: string[]) =>
    cmd.params.every((p) => p.letter !== null && letters.includes(p.letter));
  switch (cmd.word) {
    case 'M0':
    case 'M24':
    case 'M25':
    case 'M112':
      return cmd.params.length === 0 ? null : `${cmd.word} with parameters`;
    case 'M999':
      if (previous?.word !== 'M112') return 'M999 (board reset) other than right after M112';
      return cmd.params.length === 0 ? null : 'M999 with parameters';
    case 'M292': {
      if (!only('P', 'S', 'R')) return 'M292 with other parameters';
      for (const p of cmd.params) {
        if (p.letter === 'R') {
          if (p.kind !== 'expression' || !(R_NUMBER.test(p.text) || R_STRING.test(p.text)))
            return 'M292 with an R other than a number or a text';
        } else if (p.kind !== 'number' || !INTEGER.test(p.text)) return `M292 with a non-integer ${p.letter}`;
      }
      return null;
    }
    case 'M32':
    case 'M37': {
      const [p] = cmd.params;
      const letter = cmd.word === 'M32' ? null : 'P';
      if (cmd.params.length !== 1 || !p || p.letter !== letter || p.kind !== 'string')
        return `${cmd.word} without exactly one quoted file`;
      return isAbsolute(p.text) && isJobFile(p.text)
        ? null
        : `${cmd.word} of ${p.text} (not a job file in ${JOBS_DIR})`;
    }
    default:
      return cmd.word;
  }
}

/** M32/M37 resolve a relative name against the G-code folder of the moment: only absolute names. */
function isAbsolute(path: string): boolean {
  const p = path.replace(/\\/g, '/');
  return /^\d+:/.test(p) || p.startsWith('/');
}

export function classifyCode(body: string): AccessDecision {
  const t = tokenizeGcode(body);
  if (!t.ok)
    return supervisor(
      `send G-code the gateway cannot classify for certain (line ${t.line + 1}: ${t.reason})`,
    );
  if (t.commands.length === 0) return supervisor('send an empty G-code request');
  for (let k = 0; k < t.commands.length; k++) {
    const cmd = t.commands[k];
    if (!cmd) continue;
    const why = notOperator(cmd, t.commands[k - 1]);
    if (why !== null) return supervisor(`send G-code ${why}`);
  }
  const words = new Set(t.commands.map((c) => c.word));
  // Which console command this body is (the audit's commandId, the history's attribution): the
  // strongest job word in it, whatever the page says it sent.
  const job = JOB_WORDS.find(([w]) => words.has(w));
  return operator(`send ${[...words].join(', ')}`, job?.[1]);
}

/** Job words by strength: a body with M112 is an emergency stop, whatever else it holds. */
const JOB_WORDS: ReadonlyArray<readonly [string, string]> = [
  ['M112', 'duet.estop'],
  ['M0', 'duet.cancel'],
  ['M32', 'duet.start'],
  ['M37', 'duet.simulate'],
  ['M25', 'duet.pause'],
  ['M24', 'duet.resume'],
];
