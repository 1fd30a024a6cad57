/**
 * The server's log is the gateway's (gateway/log.ts): one logger, one format, every value escaped
 * (control characters never reach a log line as they are).
 */
export {
  createLogger,
  escapeControls,
  loggerFromEnv,
  type LogFields,
  type LoggerOptions,
  type LogLevel,
  type ServerLogger as Logger,
} from '../gateway/log';
