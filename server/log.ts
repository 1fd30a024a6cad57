/**
 * The server's log: plain lines for a person at a terminal, or one JSON object a line
 * (`SHOPDECK_LOG=json`) for journald, Docker and log shippers: `{ time, level, msg, …fields }`.
 */

export type LogLevel = 'info' | 'warn' | 'error';

export type LogFields = Record<string, unknown>;

export interface Logger {
  readonly json: boolean;
  info(msg: string, fields?: LogFields): void;
  warn(msg: string, fields?: LogFields): void;
  error(msg: string, fields?: LogFields): void;
  /**
   * A message for people (the start banner): in text mode `text` is printed as it is, in JSON mode
   * one entry with `msg` and `fields`.
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

function textValue(v: unknown): string {
  if (typeof v === 'string') return /[\s"=]/.test(v) || v === '' ? JSON.stringify(v) : v;
  if (v instanceof Error) return JSON.stringify(v.message);
  return JSON.stringify(v) ?? String(v);
}

export function createLogger(opts: LoggerOptions = {}): Logger {
  const json = opts.json ?? false;
  const write = opts.write ?? defaultWrite;
  const now = opts.now ?? (() => new Date());
  const emit = (level: LogLevel, msg: string, fields: LogFields = {}): void => {
    if (json) {
      const entry: LogFields = { time: now().toISOString(), level, msg };
      for (const [k, v] of Object.entries(fields)) {
        if (k in entry || v === undefined) continue;
        entry[k] = v instanceof Error ? v.message : v;
      }
      write(JSON.stringify(entry), level);
      return;
    }
    const extra = Object.entries(fields)
      .filter(([, v]) => v !== undefined)
      .map(([k, v]) => `${k}=${textValue(v)}`)
      .join(' ');
    const prefix = level === 'info' ? 'shopdeck:' : `shopdeck: ${level}:`;
    write(`${prefix} ${msg}${extra ? ` (${extra})` : ''}`, level);
  };
  return {
    json,
    info: (msg, fields) => emit('info', msg, fields),
    warn: (msg, fields) => emit('warn', msg, fields),
    error: (msg, fields) => emit('error', msg, fields),
    banner(msg, text, fields) {
      if (json) emit('info', msg, fields);
      else write(text, 'info');
    },
  };
}

/** The logger the environment asks for: JSON with `SHOPDECK_LOG=json`, plain text otherwise. */
export function loggerFromEnv(env: NodeJS.ProcessEnv): Logger {
  return createLogger({ json: (env.SHOPDECK_LOG ?? '').toLowerCase() === 'json' });
}
