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
 * What a byte outside printable ASCII would be on the wire: the link writes one byte per
 * character (latin1), so U+0118 "Ę" is 0x18 (^X, reset), U+0104 0x04 (^D, kill), U+0121 "!".
 */
function wireByteWords(ch: string): string {
  const cp = ch.codePointAt(0) ?? 0;
  const hex = `U+${cp.toString(16).toUpperCase().padStart(4, '0')}`;
  if (cp > 0xffff) return `${hex} (not one byte)`;
  const b = cp & 0xff;
  const as =
    b === 0x18
      ? '^X, a board reset'
      : b === 0x04
        ? '^D, a job kill'
        : b === 0x0a || b === 0x0d
          ? 'a line break'
          : b < 0x20 || b === 0x7f
            ? `control byte 0x${b.toString(16).padStart(2, '0')}`
            : b >= 0x80
              ? `byte 0x${b.toString(16)}`
              : `"${String.fromCharCode(b)}"`;
  return cp < 0x80 ? `${hex} (${as})` : `${hex} (the board would read ${as})`;
}

/** Printable ASCII and TAB: the only bytes a line may hold (a line is written one byte per character). */
const NOT_PRINTABLE = /[^\t\x20-\x7e]/u;

/**
 * Why a line may not be sent, or null. The line is checked as the bytes that will be written:
 * only printable ASCII and TAB (anything else is written as some other byte: U+0118 would reach
 * the board as ^X), no `!`, `~`, `%` (the board acts on them at once: a `!` in a value is a
 * feedhold), and fewer than 254 bytes with the terminator (the firmware's line buffer).
 */
export function lineProblem(line: string): string | null {
  const bad = NOT_PRINTABLE.exec(line);
  if (bad) {
    const cp = bad[0].codePointAt(0) ?? 0;
    return cp < 0x20 || cp === 0x7f
      ? `contains a control character (${wireByteWords(bad[0])})`
      : `contains a character outside printable ASCII, ${wireByteWords(bad[0])}`;
  }
  if (/[!~%]/.test(line)) return 'contains "!", "~" or "%", which the board acts on at once';
  const bytes = line.length + 1;
  if (bytes >= MAX_LINE_BYTES)
    return `${bytes} bytes with its terminator (the board takes at most ${MAX_LINE_BYTES - 1})`;
  return null;
}

/** True for `lineProblem`'s "too long" answer (413/107), false for a refused character (400/101). */
export function tooLong(problem: string): boolean {
  return problem.includes(' bytes with its terminator');
}

/**
 * The bytes of one write, or why it may not be written: a whole line (printable ASCII and TAB,
 * then "\n"), or one single-character control. The last check before the port: whatever the
 * checks before it missed, no other byte reaches the board.
 */
export function wireBytes(data: string): Buffer | string {
  if (data.length === 1 && CONTROL_BYTES.has(data.charCodeAt(0))) return Buffer.from(data, 'latin1');
  if (!data.endsWith('\n')) return 'not a whole line';
  const body = data.slice(0, -1);
  const bad = NOT_PRINTABLE.exec(body);
  if (bad) return `a character outside printable ASCII, ${wireByteWords(bad[0])}`;
  return Buffer.from(data, 'ascii');
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
