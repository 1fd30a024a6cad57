import { appendFileSync, existsSync, mkdirSync, readFileSync } from 'node:fs';
import path from 'node:path';
// The pure writer (no DOM); src/ui is the bottom layer, so the gateway and the browser share it.
import { toCsv as writeCsv } from '../src/ui/csv';

/**
 * The audit log: one JSON object per line in `<data folder>/audit.jsonl`. Appended by the
 * gateway (commands it forwarded, logins, refusals), by the browser for commands answered by
 * in-page simulators (`source: "client"`), and by `npm run user` (role changes).
 */

export type AuditType =
  | 'command'
  | 'refused'
  | 'login'
  | 'login-failed'
  | 'logout'
  | 'session-expired'
  | 'elevate'
  | 'elevate-failed'
  | 'elevate-end'
  | 'user-added'
  | 'user-removed'
  | 'role-change'
  | 'password-change'
  /** A controller's TLS certificate trusted on first use, or forgotten by a supervisor. */
  | 'tls-trust'
  | 'tls-forget';

export type AuditResult = 'ok' | 'error' | 'refused' | 'failed';

export interface AuditEntry {
  /** ISO time */
  time: string;
  type: AuditType;
  result: AuditResult;
  /** Who: a user name, "anonymous" in open mode, the OS user for the command line. */
  user: string;
  source: 'gateway' | 'client' | 'cli';
  machine?: string;
  method?: string;
  /** Controller path with query, secrets redacted. */
  path?: string;
  /** The `X-Shopdeck-Command` id the client sent ("xtool.pause"). */
  commandId?: string;
  /** What the request does, from the family's access declaration. */
  label?: string;
  /** Controller's HTTP status. */
  status?: number;
  /** The outcome in words, as the client saw it ("job paused"). */
  detail?: string;
  /** Error text when there was no answer, or the reason for a refusal. */
  error?: string;
  /** Role that was needed (refusals) or granted (role changes, elevation). */
  role?: string;
  address?: string;
  /** A supervisor acting on an operator's session through PIN elevation. */
  onBehalfOf?: string;
}

export interface AuditQuery {
  offset?: number;
  limit?: number;
  machine?: string;
  user?: string;
  result?: string;
  /** ms since epoch or ISO, inclusive */
  from?: number;
  to?: number;
  /** Only these machines (a user limited to some machines); entries without a machine stay. */
  machines?: readonly string[] | null;
}

export const AUDIT_FILE = 'audit.jsonl';

export class AuditLog {
  readonly file: string;

  constructor(readonly dataDir: string) {
    this.file = path.join(dataDir, AUDIT_FILE);
  }

  append(entry: Omit<AuditEntry, 'time'> & { time?: string }): AuditEntry {
    const full: AuditEntry = { time: entry.time ?? new Date().toISOString(), ...entry } as AuditEntry;
    mkdirSync(this.dataDir, { recursive: true });
    appendFileSync(this.file, JSON.stringify(full) + '\n', { encoding: 'utf8', mode: 0o600 });
    return full;
  }

  /** Every entry, oldest first. Lines that are not JSON are skipped. */
  all(): AuditEntry[] {
    if (!existsSync(this.file)) return [];
    const out: AuditEntry[] = [];
    for (const line of readFileSync(this.file, 'utf8').split('\n')) {
      if (!line.trim()) continue;
      try {
        const e = JSON.parse(line) as unknown;
        if (e && typeof e === 'object' && typeof (e as AuditEntry).time === 'string')
          out.push(e as AuditEntry);
      } catch {
        // a torn line (crash while writing): skip it
      }
    }
    return out;
  }

  /** Filtered, newest first. */
  filtered(q: AuditQuery): AuditEntry[] {
    const list = this.all().filter((e) => {
      if (q.machine && e.machine !== q.machine) return false;
      if (q.machines && e.machine !== undefined && !q.machines.includes(e.machine)) return false;
      if (q.user && e.user !== q.user && e.onBehalfOf !== q.user) return false;
      if (q.result && e.result !== q.result) return false;
      if (q.from !== undefined || q.to !== undefined) {
        const t = Date.parse(e.time);
        if (q.from !== undefined && t < q.from) return false;
        if (q.to !== undefined && t > q.to) return false;
      }
      return true;
    });
    return list.reverse();
  }

  query(q: AuditQuery): { entries: AuditEntry[]; total: number } {
    const list = this.filtered(q);
    const offset = Math.max(0, q.offset ?? 0);
    const limit = Math.min(1000, Math.max(1, q.limit ?? 50));
    return { entries: list.slice(offset, offset + limit), total: list.length };
  }
}

function parseTime(v: string | null): number | undefined {
  if (!v) return undefined;
  if (/^\d+$/.test(v)) return Number(v);
  const t = Date.parse(v);
  return Number.isNaN(t) ? undefined : t;
}

export function auditQueryFrom(params: URLSearchParams): AuditQuery {
  const num = (k: string): number | undefined => {
    const v = params.get(k);
    if (v === null || v === '' || !/^\d+$/.test(v)) return undefined;
    return Number(v);
  };
  return {
    offset: num('offset'),
    limit: num('limit'),
    machine: params.get('machine') || undefined,
    user: params.get('user') || undefined,
    result: params.get('result') || undefined,
    from: parseTime(params.get('from')),
    to: parseTime(params.get('to')),
  };
}

export const CSV_COLUMNS: Array<keyof AuditEntry> = [
  'time',
  'type',
  'result',
  'user',
  'onBehalfOf',
  'machine',
  'method',
  'path',
  'commandId',
  'label',
  'status',
  'detail',
  'error',
  'role',
  'address',
  'source',
];

/**
 * The audit log as CSV, through the console's one writer (src/ui/csv.ts: RFC 4180, formula
 * defusing). User names, paths, labels and controller messages are not ours: a cell such as
 * `=HYPERLINK(…)` is written as text, never as a formula a spreadsheet would run. With a UTF-8
 * byte order mark: the export is opened in spreadsheets, and user names are not ASCII-only.
 */
export function toCsv(entries: readonly AuditEntry[]): string {
  return writeCsv(
    CSV_COLUMNS,
    entries.map((e) => CSV_COLUMNS.map((c) => e[c])),
    { bom: true },
  );
}
