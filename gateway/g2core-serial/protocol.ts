/**
 * The g2core / TinyG serial JSON protocol as data: what the board sends (parsed, untrusted) and
 * what the host writes. Sources: ../shared/fixtures/g2core/protocol-notes.json and the captures
 * in ../shared/fixtures/g2core/sessions (SOURCES.md). Node-only (never imported by the page).
 */

/** Single-character controls: written between lines, never queued, no `{r}` of their own. */
export const CTRL = {
  feedhold: '!',
  cycleStart: '~',
  /** Honoured only in feedhold or right after `!`; anywhere else it is a program delimiter. */
  flush: '%',
  kill: '\x04',
  reset: '\x18',
  enquiry: '\x05',
} as const;

export const CONTROL_BYTES: ReadonlySet<number> = new Set(Object.values(CTRL).map((c) => c.charCodeAt(0)));

/** A line of this many bytes or more (terminator included) is refused before it is sent. */
export const MAX_LINE_BYTES = 254;

/** Lines in flight (sent, no `{r}` yet): the wiki's and FabMo's 4, so a feedhold is never stuck behind a long brigade. */
export const DEFAULT_WINDOW = 4;

/** Longest line read from the board: anything longer is noise (or hostile) and is dropped. */
export const MAX_RX_LINE = 16 * 1024;

/**
 * USB ids of g2core and TinyG boards (for `"serial": "auto"`): g2core's own id (1d50:606d,
 * OpenMoko-assigned), the Arduino Due native and programming ports (2341:003d, 2341:003e) and
 * TinyG's FTDI FT231X (0403:6015).
 */
export const BOARD_USB_IDS: ReadonlyArray<{ vendorId: string; productId: string; board: string }> = [
  { vendorId: '1d50', productId: '606d', board: 'g2core' },
  { vendorId: '2341', productId: '003d', board: 'Arduino Due (g2core)' },
  { vendorId: '2341', productId: '003e', board: 'Arduino Due (g2core)' },
  { vendorId: '0403', productId: '6015', board: 'TinyG (FTDI)' },
];

export type Json = null | boolean | number | string | Json[] | { [k: string]: Json };
export type JsonObject = { [k: string]: Json };

/** One line from the board, classified. */
export type BoardMessage =
  /** The start-up banner (`msg: "SYSTEM READY"`): the board (re)started. */
  | { type: 'banner'; info: JsonObject }
  /** A response: `r` (may be empty for G-code lines) and the status code `f[1]`. */
  | { type: 'response'; r: JsonObject; status: number }
  | { type: 'sr'; sr: JsonObject }
  | { type: 'qr'; qr: number }
  | { type: 'er'; status: number; msg: string }
  | { type: 'ack' }
  /** The JSON-mode companion `{"err":{…}}` some builds send after a failed response: not a response. */
  | { type: 'err'; code: number; msg: string }
  /** Anything else: noise, text-mode output, a line cut by a reset. */
  | { type: 'noise'; text: string };

export function isObject(v: unknown): v is JsonObject {
  return typeof v === 'object' && v !== null && !Array.isArray(v);
}

/** `f[1]` only: f[0] (revision) and f[2..] (length, buffers, checksum) are opaque. */
function footerStatus(f: unknown): number | null {
  if (!Array.isArray(f) || f.length < 2) return null;
  const s: unknown = f[1];
  return typeof s === 'number' && Number.isInteger(s) && s >= 0 && s < 256 ? s : null;
}

/** Parses one line from the board. Never throws: what is not understood is `noise`. */
export function parseBoardLine(line: string): BoardMessage {
  const text = line.trim();
  let v: unknown;
  try {
    v = JSON.parse(text);
  } catch {
    return { type: 'noise', text: text.slice(0, 200) };
  }
  if (!isObject(v)) return { type: 'noise', text: text.slice(0, 200) };
  if ('r' in v && isObject(v.r)) {
    const r = v.r;
    // Some old TinyG builds put the footer inside `r` (node-g2core-api checks both).
    const status = footerStatus(v.f) ?? footerStatus(r.f) ?? 0;
    const { f: _inner, ...rest } = r;
    if (typeof rest.msg === 'string' && rest.msg === 'SYSTEM READY' && 'fb' in rest)
      return { type: 'banner', info: rest };
    return { type: 'response', r: rest, status };
  }
  if ('sr' in v && isObject(v.sr)) return { type: 'sr', sr: v.sr };
  if ('qr' in v && typeof v.qr === 'number') return { type: 'qr', qr: v.qr };
  if ('er' in v && isObject(v.er)) {
    const st = typeof v.er.st === 'number' ? v.er.st : 0;
    return { type: 'er', status: st, msg: typeof v.er.msg === 'string' ? v.er.msg.slice(0, 200) : '' };
  }
  if ('ack' in v) return { type: 'ack' };
  if ('err' in v && isObject(v.err)) {
    const code = typeof v.err.code === 'number' ? v.err.code : 0;
    return { type: 'err', code, msg: typeof v.err.msg === 'string' ? v.err.msg.slice(0, 200) : '' };
  }
  return { type: 'noise', text: text.slice(0, 200) };
}

/**
 * Why a line may not be sent, or null: control characters and `!`, `~`, `%` would act at once
 * (a `!` in a value is a feedhold), and a line of 254 bytes or more overruns the firmware's
 * line buffer.
 */
export function lineProblem(line: string): string | null {
  // eslint-disable-next-line no-control-regex
  if (/[\x00-\x1f\x7f]/.test(line)) return 'contains a control character';
  if (/[!~%]/.test(line)) return 'contains "!", "~" or "%", which the board acts on at once';
  const bytes = Buffer.byteLength(line, 'utf8') + 1;
  if (bytes >= MAX_LINE_BYTES)
    return `${bytes} bytes with its terminator (the board takes at most ${MAX_LINE_BYTES - 1})`;
  return null;
}

/**
 * A G-code line as it is sent: comments (`(…)`, `;…`) removed, as hosts do (the firmware ignores
 * them, and a comment may hold `!` or `%`). JSON lines are kept as they are. Null: nothing left.
 */
export function sendableLine(line: string): string | null {
  const t = line.trim();
  if (t === '%') return null; // a program delimiter line
  if (t.startsWith('{')) return t;
  const code = t
    .replace(/\([^)]*\)/g, '')
    .replace(/;.*$/, '')
    .trim();
  return code === '' ? null : code;
}

/** A JSON request line, `{"xvm":null}` (strict JSON; the firmware accepts it as well as relaxed). */
export function jsonLine(key: string, value: Json): string {
  return JSON.stringify({ [key]: value });
}

/** Most keys kept from a status report or a banner: a board that sends more is cut short. */
export const MAX_REPORT_KEYS = 100;

/**
 * The scalar values of a status report or banner, as far as they can be shown: keys of 1 to 16
 * letters and digits, numbers, booleans, null, and text cut to 64 characters. Anything else
 * (nested objects, long keys, a flood of keys) is dropped: the board's bytes are untrusted.
 */
export function scalarsOf(o: JsonObject): Record<string, string | number | boolean | null> {
  const out: Record<string, string | number | boolean | null> = {};
  let n = 0;
  for (const [k, v] of Object.entries(o)) {
    if (n >= MAX_REPORT_KEYS) break;
    if (!/^[A-Za-z0-9]{1,16}$/.test(k)) continue;
    if (typeof v === 'string') out[k] = v.slice(0, 64);
    else if (typeof v === 'number' || typeof v === 'boolean' || v === null) out[k] = v;
    else continue;
    n++;
  }
  return out;
}
