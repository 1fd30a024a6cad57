import {
  operator,
  read,
  supervisor,
  type AccessDecision,
  type AccessPolicy,
  type AccessRequest,
  type BodyNeeded,
} from '../../fleet/access';
import { classifyCode } from './gcode-access';
import { isJobFile, normaliseDuetPath, openToViewers } from './paths';

/**
 * Who may send which DSF request (the gateway enforces it, the UI hides or disables by it); an
 * ALLOW-LIST: what is not recognised for certain needs a supervisor, GETs included (`rr_gcode`,
 * `rr_delete`, plugin endpoints are GETs). Viewer: the model, connect/noop/disconnect, listings,
 * job files under `0:/gcodes/` and the height map (no other file: config.g holds M551/M587
 * secrets). Operator: job control by G-code (`classifyCode`), job uploads. Supervisor: the rest.
 */

export {
  classifyCode,
  tokenizeGcode,
  type GcodeCommand,
  type GcodeParam,
  type GcodeTokens,
} from './gcode-access';
export { HEIGHT_MAP, isJobFile, JOBS_DIR, normaliseDuetPath, openToViewers } from './paths';

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
