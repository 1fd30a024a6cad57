import type { PortInfo, PortOpener } from '../../../fleet/server-part';
import { BOARD_USB_IDS, type BoardMessage, type Json, type JsonObject } from './protocol';

/** The serial link's states, errors, options and port helpers (the link itself: link.ts). */

/** JSON requests in flight at once (each is answered at once; this bounds the board's input buffer). */
export const JSON_LANE = 4;

/** Keys a G-code line's answer may carry (`js.echo_json_gcode_block`, line numbers, messages). */
export const GCODE_ANSWER_KEYS = new Set(['gc', 'n', 'msg']);

/**
 * The key a JSON line's answer names (`{"xvm":5000}` → `xvm`), lower-cased; null for a G-code
 * line, and for `{"gc":"G0 X1"}`, which the board answers as G-code (`{"r":{}}`, the captures).
 */
export function jsonKeyOf(line: string): string | null {
  if (!line.startsWith('{')) return null;
  const m = /^\{\s*"?([A-Za-z0-9_]+)"?\s*:/.exec(line);
  const k = m?.[1]?.toLowerCase() ?? '';
  return GCODE_ANSWER_KEYS.has(k) ? null : k;
}

export type LinkState =
  | { state: 'connecting' }
  | { state: 'online'; since: number }
  /** The port does not exist (unplugged), or `auto` found no board. */
  | { state: 'unplugged'; detail: string }
  /** Another program holds the port. */
  | { state: 'busy'; detail: string }
  | { state: 'error'; detail: string }
  | { state: 'closed' };

/** The board could not answer: not connected, gone, reset (`reset`), or silent past a deadline. */
export class LinkDown extends Error {
  constructor(
    message: string,
    readonly reset = false,
  ) {
    super(message);
  }
}

/** A write refused by the last check before the port (a byte outside printable ASCII). */
export class UnsafeBytes extends Error {}

export interface Reply {
  r: JsonObject;
  status: number;
}

export interface InFlight {
  line: string;
  /** The key a JSON request expects back (null for a G-code line). */
  key: string | null;
  /** A JSON line (answered at once by the board): a job's is in flight alone. */
  json?: boolean;
  done(reply: Reply | Error): void;
}

/** A line of an operation or job offered by the streamer when a slot is free. */
export interface DataLine {
  line: string;
  done(reply: Reply | Error): void;
}

export interface LinkOptions {
  /** A device path, or 'auto': the first port with a g2core/TinyG USB id. */
  path: string;
  baudRate: number;
  opener: PortOpener;
  window?: number;
  /** After opening, how long to wait for a start-up banner before the setup is sent. */
  bannerWaitMs?: number;
  /** Reconnect attempts: first after this, doubling up to 10 s. */
  retryMs?: number;
  /** A JSON request with no `{r}` within this fails (the line may have reached the board). */
  requestTimeoutMs?: number;
  /** Setup sent on every (re)connect; the answers are awaited before the link is online. */
  setup?: Array<[string, Json]>;
  setTimeout?: (fn: () => void, ms: number) => unknown;
  clearTimeout?: (t: unknown) => void;
  now?: () => number;
}

export interface LinkListener {
  message?(m: BoardMessage): void;
  state?(s: LinkState): void;
  /** A banner came while connected: the board reset (new banner), everything in flight is lost. */
  reset?(info: JsonObject): void;
}

/** Open errors worded for the machine page: the OS says "busy" or "locked" for a held port. */
export function classifyOpenError(e: unknown, path: string): LinkState {
  const msg = e instanceof Error ? e.message : String(e);
  const code = (e as { code?: unknown } | null)?.code;
  if (/Permission denied/i.test(msg) || code === 'EACCES')
    return {
      state: 'error',
      detail: `${path}: no permission to open it (on Linux, add the console's user to the "dialout" group)`,
    };
  if (/lock|busy|EBUSY|Resource temporarily unavailable|Access denied/i.test(msg) || code === 'EBUSY')
    return { state: 'busy', detail: `${path} is held by another program (close it to let Shopdeck connect)` };
  if (/ENOENT|does not exist|No such file|not found|cannot find/i.test(msg) || code === 'ENOENT')
    return { state: 'unplugged', detail: `${path} is not there: the board is unplugged or switched off` };
  return { state: 'error', detail: `${path} cannot be opened: ${msg.slice(0, 200)}` };
}

export function pickBoardPort(ports: PortInfo[]): PortInfo | null {
  return (
    ports.find((p) =>
      BOARD_USB_IDS.some(
        (id) => p.vendorId?.toLowerCase() === id.vendorId && p.productId?.toLowerCase() === id.productId,
      ),
    ) ?? null
  );
}
