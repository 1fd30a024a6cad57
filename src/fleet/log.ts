import { createStore, type StoreApi } from 'zustand/vanilla';

/** One line of a machine's log: console replies, controller messages, commands, link events. */
export interface LogEntry {
  seq: number;
  /** ms since epoch */
  at: number;
  level: 'info' | 'warning' | 'error' | 'debug';
  /** Where it came from: 'link', 'command', 'console', 'controller', 'protocol', … */
  source: string;
  text: string;
}

export interface LogState {
  entries: LogEntry[];
}

export const LOG_LIMIT = 2000;

export class MachineLog {
  readonly store: StoreApi<LogState> = createStore<LogState>(() => ({ entries: [] }));
  private seq = 0;

  constructor(
    readonly machineId: string,
    private readonly now: () => number = Date.now,
  ) {}

  add(level: LogEntry['level'], source: string, text: string, at?: number): LogEntry {
    const entry: LogEntry = { seq: ++this.seq, at: at ?? this.now(), level, source, text };
    this.store.setState((s) => {
      const entries = s.entries.length >= LOG_LIMIT ? s.entries.slice(-LOG_LIMIT + 1) : s.entries.slice();
      entries.push(entry);
      return { entries };
    });
    if (level === 'error' && typeof console !== 'undefined' && !import.meta.env?.VITEST) {
      console.warn(`[${this.machineId}] ${source}: ${text}`);
    }
    return entry;
  }

  info(source: string, text: string): LogEntry {
    return this.add('info', source, text);
  }
  warn(source: string, text: string): LogEntry {
    return this.add('warning', source, text);
  }
  error(source: string, text: string): LogEntry {
    return this.add('error', source, text);
  }

  clear(): void {
    this.store.setState({ entries: [] });
  }
}
