import { pino, type DestinationStream, type Logger as PinoLogger } from 'pino';

/**
 * The console's one log (the gateway's and the server's: `server/log.ts` re-exports it), on pino:
 * one JSON object a line (`SHOPDECK_LOG=json`) for journald, Docker and log shippers,
 * `{ level, time, …fields, msg }`, or plain lines for a person at a terminal. Text lines start
 * `shopdeck:` (info) or `shopdeck: <level>:`. The server hands its logger to the gateway
 * (`GatewayOptions.log`); the gateway's `Logger` is the part of it the gateway uses.
 *
 * Text is kept (not pino's JSON everywhere, nor pino-pretty): the operator's terminal, the server's
 * tests and the docs read these lines, and a small destination turning pino's line into text is
 * simpler than a second dependency or changing every reader. pino writes synchronously to it.
 *
 * Every value comes escaped: job names, alarm words, file names and user names come from
 * controllers and people, and a newline or a terminal escape in one must not forge a line or
 * rewrite the operator's terminal. Control characters (C0, DEL, C1) and the Unicode line and
 * paragraph separators are written as `\n`, `\r`, `\t` or `\u001b`-style escapes, in the
 * message and in every field, in text and in JSON: one call is always exactly one line.
 */

export type LogLevel = 'info' | 'warn' | 'error';

export type LogFields = Record<string, unknown>;

export interface Logger {
  readonly json: boolean;
  info(msg: string, fields?: LogFields): void;
  warn(msg: string, fields?: LogFields): void;
  error(msg: string, fields?: LogFields): void;
}

/** The server's logger: the gateway's, and the start banner. */
export interface ServerLogger extends Logger {
  /**
   * A message for people (the start banner): in text mode `text` is printed line by line as it
   * is (escaped, its own newlines kept), in JSON mode one entry with `msg` and `fields`.
   */
  banner(msg: string, text: string, fields?: LogFields): void;
}

export interface LoggerOptions {
  json?: boolean;
  /** Where lines go (default: info to stdout, warnings and errors to stderr). */
  write?: (line: string, level: LogLevel) => void;
  now?: () => Date;
}

function defaultWrite(line: string, level: LogLevel): void {
  (level === 'info' ? process.stdout : process.stderr).write(line + '\n');
}

// eslint-disable-next-line no-control-regex
const CONTROL = /[\u0000-\u001f\u007f-\u009f\u2028\u2029]/g;
const SHORT: Readonly<Record<string, string>> = { '\n': '\\n', '\r': '\\r', '\t': '\\t' };

/** Control characters (and U+2028/U+2029) as visible escapes: `\n`, `\r`, `\t`, `\u001b`. */
export function escapeControls(text: string): string {
  return text.replace(CONTROL, (c) => SHORT[c] ?? `\\u${c.charCodeAt(0).toString(16).padStart(4, '0')}`);
}

/** pino's JSON escapes C0 controls itself; DEL, C1 and the separators are escaped here too. */
const JSON_LEFT = /[\u007f-\u009f\u2028\u2029]/g;
function escapeJsonLine(line: string): string {
  return line.replace(JSON_LEFT, (c) => `\\u${c.charCodeAt(0).toString(16).padStart(4, '0')}`);
}

function textValue(v: unknown): string {
  if (typeof v === 'string') return /[\s"=]/.test(v) || v === '' ? JSON.stringify(v) : v;
  return JSON.stringify(v) ?? String(v);
}

/** pino's entry as a text line: `shopdeck: [level: ]msg (k=v …)`, every part escaped. */
function textLine(json: string, level: LogLevel): string {
  const { level: _level, time: _time, msg, ...fields } = JSON.parse(json) as LogFields;
  const extra = Object.entries(fields)
    .map(([k, v]) => `${escapeControls(k)}=${escapeControls(textValue(v))}`)
    .join(' ');
  const prefix = level === 'info' ? 'shopdeck:' : `shopdeck: ${level}:`;
  return `${prefix} ${escapeControls(typeof msg === 'string' ? msg : '')}${extra ? ` (${extra})` : ''}`;
}

/** One pino destination per level (pino's multistream with `dedupe` hands each entry to one). */
function destination(
  level: LogLevel,
  json: boolean,
  write: NonNullable<LoggerOptions['write']>,
): DestinationStream {
  return {
    write(line: string): void {
      const entry = line.endsWith('\n') ? line.slice(0, -1) : line;
      write(json ? escapeJsonLine(entry) : textLine(entry, level), level);
    },
  };
}

/** The fields as logged: no `undefined`, an Error as its message, never over time, level or msg. */
function cleanFields(fields: LogFields): LogFields {
  const out: LogFields = {};
  for (const [k, v] of Object.entries(fields)) {
    if (k === 'time' || k === 'level' || k === 'msg' || v === undefined) continue;
    out[k] = v instanceof Error ? v.message : v;
  }
  return out;
}

export function createLogger(opts: LoggerOptions = {}): ServerLogger {
  const json = opts.json ?? false;
  const write = opts.write ?? defaultWrite;
  const now = opts.now ?? (() => new Date());
  const levels: LogLevel[] = ['info', 'warn', 'error'];
  const log: PinoLogger = pino(
    {
      level: 'info',
      base: undefined,
      messageKey: 'msg',
      timestamp: () => `,"time":"${now().toISOString()}"`,
      formatters: { level: (label) => ({ level: label }) },
      // Errors are turned into their message by cleanFields: no serializer adds a stack or a type.
      serializers: {},
    },
    pino.multistream(
      levels.map((level) => ({ level, stream: destination(level, json, write) })),
      { dedupe: true },
    ),
  );
  const emit = (level: LogLevel, msg: string, fields: LogFields = {}): void => {
    log[level](cleanFields(fields), msg);
  };
  return {
    json,
    info: (msg, fields) => emit('info', msg, fields),
    warn: (msg, fields) => emit('warn', msg, fields),
    error: (msg, fields) => emit('error', msg, fields),
    banner(msg, text, fields) {
      // For a person reading the terminal, not a log entry: printed as it is (escaped) in text mode.
      if (json) emit('info', msg, fields);
      else write(text.split('\n').map(escapeControls).join('\n'), 'info');
    },
  };
}

/** The logger the environment asks for: JSON with `SHOPDECK_LOG=json`, plain text otherwise. */
export function loggerFromEnv(env: NodeJS.ProcessEnv = process.env): ServerLogger {
  return createLogger({ json: (env.SHOPDECK_LOG ?? '').toLowerCase() === 'json' });
}

// ---------------------------------------------------------------- machines going offline/online

/**
 * Why a controller could not be reached, in a few words, or null when the error says nothing
 * about reaching it (a changed certificate, a refused redirect, an answer too large: the
 * controller was there). Used for the offline/online lines, never shown to viewers.
 */
export function unreachableReason(
  e: { code?: unknown; message?: unknown } | null | undefined,
  timedOut: boolean,
): string | null {
  if (timedOut) return 'no answer in time';
  switch (typeof e?.code === 'string' ? e.code : '') {
    case 'ECONNREFUSED':
      return 'connection refused';
    case 'ECONNRESET':
    case 'EPIPE':
      return 'connection reset';
    case 'ETIMEDOUT':
      return 'connection timed out';
    case 'EHOSTUNREACH':
    case 'EHOSTDOWN':
      return 'host unreachable';
    case 'ENETUNREACH':
    case 'ENETDOWN':
      return 'network unreachable';
    case 'ENOTFOUND':
    case 'EAI_AGAIN':
      return 'address not resolved';
    default:
      // The ws library's handshake timeout and our own timeouts carry no code.
      return typeof e?.message === 'string' && /timed out|did not answer within/i.test(e.message)
        ? 'no answer in time'
        : null;
  }
}

export type Reachable = 'online' | 'offline' | 'unknown';

/**
 * Whether each machine's controller answers, as the gateway sees it: one log line when a machine
 * goes offline (the first failure to reach it after it answered, or since the start) and one
 * when it comes back (the first answer after failures). Per machine, not per request.
 */
export class Reachability {
  private readonly state = new Map<string, 'online' | 'offline'>();

  constructor(private readonly log: Logger) {}

  /** The controller answered (any HTTP status, a WebSocket handshake). */
  up(machine: string): void {
    const was = this.state.get(machine);
    this.state.set(machine, 'online');
    if (was === 'offline') this.log.info(`machine ${machine} online`, { machine, event: 'online' });
  }

  /** The controller could not be reached (`unreachableReason`); `error`: the system's words, redacted. */
  down(machine: string, reason: string, error?: string): void {
    const was = this.state.get(machine);
    this.state.set(machine, 'offline');
    if (was !== 'offline')
      this.log.warn(`machine ${machine} offline: ${reason}`, { machine, event: 'offline', reason, error });
  }

  status(machine: string): Reachable {
    return this.state.get(machine) ?? 'unknown';
  }
}
