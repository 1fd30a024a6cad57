import { readFileSync, readdirSync, renameSync, statSync } from 'node:fs';
import path from 'node:path';
import { openHistoryDb, type Db } from './history/db';
import { loggerFromEnv, type Logger } from './log';

/**
 * The audit log: a table (`audit`) of the console's SQLite database, `<data>/history.sqlite`,
 * beside the production history (migration 3 of history/db.ts). Written by the gateway (commands
 * it forwarded to hardware or to its own simulators, logins, refusals, changes of users, trust and
 * settings, what its watch saw) and by `npm run user` (role changes), each entry committed before
 * `append` returns. `source: "client"` only appears in entries written before the demo fleet moved
 * into the server, when the page audited its own simulators.
 *
 * - Two kinds of entries, each with its own retention: **records** (commands, logins, logouts,
 *   elevations, user, role, trust and settings changes, alarm acknowledgements, the watch's
 *   machine events) are kept `recordDays` (400 days); **refusals** (`refused`, `login-failed`,
 *   `elevate-failed`: what anyone can make the gateway write, as often as they like) are kept
 *   `refusalDays` (30 days) and at most `refusalMax` rows (100,000; the oldest refusals go first).
 *   Refusals never evict records: a flood of refusals can only push out older refusals.
 * - A command is written twice: `begin` commits its entry (`result: "pending"`) before it is
 *   forwarded, `finish` writes its outcome after the answer. A gateway that is killed in between
 *   leaves the entry pending, and the next start marks it `error` ("the console stopped before the
 *   answer"): a command is never forwarded without its entry on disk.
 * - The audit's connection commits with `synchronous=FULL` (an fsync per commit: the entry is on
 *   disk, a power cut included, when `append` returns), the history's with NORMAL.
 * - On first start, an `audit.jsonl` and its rotated files (`audit.<n>.jsonl`) of an older
 *   Shopdeck are imported once (in one transaction, marked in `audit_imports`) and renamed
 *   `<name>.imported`.
 * - If the database cannot be opened or written, `append` and `begin` throw: the gateway logs it
 *   and refuses commands (503) rather than forward one it cannot audit. Opening is tried again
 *   on a later write (at most every `REOPEN_MS`).
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
  | 'tls-forget'
  /** What the gateway's watch saw a machine do (watch.ts): job started/paused/ended, alarms. */
  | 'machine'
  /** A person acknowledged an alarm (the alarm centre, alarms.ts). */
  | 'alarm-ack'
  /** A supervisor changed the server settings (the alarm webhook). */
  | 'settings';

/** `pending`: a command forwarded whose outcome is not written yet. */
export type AuditResult = 'ok' | 'error' | 'refused' | 'failed' | 'pending';

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
  /**
   * The command as the GATEWAY classified the request (the family's access rule,
   * `AccessDecision.id`: "xtool.pause"); the history believes only this one.
   */
  commandId?: string;
  /** The `X-Shopdeck-Command` the page sent: its own name for the command, a label only (not trusted). */
  clientCommand?: string;
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

export type AuditInput = Omit<AuditEntry, 'time'> & { time?: string };

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

export interface AuditRetention {
  /** Commands, logins, changes, machine events: days kept (SHOPDECK_AUDIT_DAYS). */
  recordDays: number;
  /** Refusals: days kept (SHOPDECK_AUDIT_REFUSAL_DAYS) … */
  refusalDays: number;
  /** … and at most this many, the newest (SHOPDECK_AUDIT_REFUSAL_MAX). */
  refusalMax: number;
}

export const DEFAULT_AUDIT_RETENTION: AuditRetention = {
  recordDays: 400,
  refusalDays: 30,
  refusalMax: 100_000,
};

export const AUDIT_DB_FILE = 'history.sqlite';
/** The JSONL file of older versions (imported once). */
export const AUDIT_FILE = 'audit.jsonl';

export interface AuditLogOptions {
  retention?: Partial<AuditRetention>;
  log?: Logger;
  now?: () => number;
  /** `server`: the gateway (pending commands of a previous run are closed at start). Default `tool`. */
  role?: 'server' | 'tool';
}

/** Entries anyone can make the gateway write as often as they like: short retention, bounded. */
export const REFUSAL_TYPES: ReadonlySet<AuditType> = new Set<AuditType>([
  'refused',
  'login-failed',
  'elevate-failed',
]);

const DAY_MS = 86_400_000;
const REOPEN_MS = 5000;
const PRUNE_EVERY_MS = 3_600_000;
const CSV_PAGE = 500;
const KILLED =
  'not confirmed: the console stopped before the answer came (it may or may not have reached the machine)';

function kindOf(e: AuditEntry): 'record' | 'refusal' {
  return REFUSAL_TYPES.has(e.type) ? 'refusal' : 'record';
}

interface Row {
  id: number;
  entry: string;
}

/** Filters as SQL (`?` parameters in order). */
function where(q: AuditQuery): { sql: string; args: Array<string | number> } {
  const parts: string[] = [];
  const args: Array<string | number> = [];
  const add = (sql: string, ...values: Array<string | number>): void => {
    parts.push(sql);
    args.push(...values);
  };
  if (q.machine) add('machine = ?', q.machine);
  if (q.machines)
    add('(machine IS NULL OR machine IN (SELECT value FROM json_each(?)))', JSON.stringify(q.machines));
  if (q.user) add('(user = ? OR on_behalf_of = ?)', q.user, q.user);
  if (q.result) add('result = ?', q.result);
  if (q.from !== undefined) add('at >= ?', q.from);
  if (q.to !== undefined) add('at <= ?', q.to);
  return { sql: parts.length ? `WHERE ${parts.join(' AND ')}` : '', args };
}

function parse(row: Row): AuditEntry {
  return JSON.parse(row.entry) as AuditEntry;
}

export class AuditLog {
  /** The database file. */
  readonly file: string;
  private readonly retention: AuditRetention;
  private readonly log: Logger;
  private readonly now: () => number;
  private readonly role: 'server' | 'tool';
  private db: Db | null = null;
  private closed = false;
  private triedAt = Number.NEGATIVE_INFINITY;
  private prunedAt = Number.NEGATIVE_INFINITY;
  private refusals = 0;
  private swept = false;
  /** Why the database is not open (null: it is, or was not tried yet). */
  problem: string | null = null;

  constructor(
    readonly dataDir: string,
    opts: AuditLogOptions = {},
  ) {
    this.file = path.join(dataDir, AUDIT_DB_FILE);
    this.retention = { ...DEFAULT_AUDIT_RETENTION, ...opts.retention };
    this.log = opts.log ?? loggerFromEnv();
    this.now = opts.now ?? Date.now;
    this.role = opts.role ?? 'tool';
    // A tool (npm run user) holds the database only for each write or read.
    this.closed = this.role === 'tool';
    if (this.role === 'server') {
      try {
        this.open();
      } catch {
        // logged by open(); tried again at the next write
      }
    }
  }

  // ---------------------------------------------------------------- the database

  /** The open database, opened (migrated, old files imported) if needed; throws when it cannot be. */
  private open(): Db {
    if (this.db) return this.db;
    const t = this.now();
    if (this.problem && t - this.triedAt < REOPEN_MS) throw new Error(this.problem);
    this.triedAt = t;
    let db: Db | null = null;
    try {
      db = openHistoryDb(this.file).db;
      db.pragma('synchronous = FULL');
      this.importJsonl(db);
      if (this.role === 'server' && !this.swept) {
        // Commands of a previous run that never got their outcome (the process was killed).
        this.swept = true;
        const pending = db.prepare("SELECT id, entry FROM audit WHERE result = 'pending'").all() as Row[];
        const close = db.prepare("UPDATE audit SET result = 'error', entry = ? WHERE id = ?");
        db.transaction(() => {
          for (const r of pending)
            close.run(JSON.stringify({ ...parse(r), result: 'error', error: KILLED }), r.id);
        })();
      }
      this.refusals = (
        db.prepare("SELECT COUNT(*) AS n FROM audit WHERE kind = 'refusal'").get() as { n: number }
      ).n;
      if (this.problem) this.log.info('the audit log is written again', { file: this.file });
      this.problem = null;
      this.db = db;
      if (t - this.prunedAt > PRUNE_EVERY_MS) this.prune();
      return db;
    } catch (e) {
      db?.close();
      const why = e instanceof Error ? e.message : String(e);
      if (this.problem !== why)
        this.log.error('the audit log cannot be opened: commands are refused until it can', {
          file: this.file,
          error: why,
        });
      this.problem = why;
      throw e;
    }
  }

  /** `audit.jsonl` and `audit.<n>.jsonl` of an older Shopdeck: imported once, then renamed. */
  private importJsonl(db: Db): void {
    let names: string[];
    try {
      names = readdirSync(this.dataDir).filter((n) => n === AUDIT_FILE || /^audit\.\d+\.jsonl$/.test(n));
    } catch {
      return;
    }
    if (!names.length) return;
    // Oldest first: the highest number, then … audit.1.jsonl, then audit.jsonl.
    const num = (n: string): number => (n === AUDIT_FILE ? 0 : Number(/\d+/.exec(n)?.[0] ?? 0));
    names.sort((a, b) => num(b) - num(a));
    const done = db.prepare('SELECT 1 FROM audit_imports WHERE file = ? AND size = ?');
    const mark = db.prepare('INSERT INTO audit_imports (file, size, at) VALUES (?, ?, ?)');
    const insert = this.inserter(db);
    let count = 0;
    let skipped = 0;
    const imported: string[] = [];
    db.transaction(() => {
      for (const name of names) {
        const file = path.join(this.dataDir, name);
        const size = statSync(file).size;
        imported.push(name);
        if (done.get(name, size)) continue;
        for (const line of readFileSync(file, 'utf8').split('\n')) {
          if (!line.trim()) continue;
          try {
            const e = JSON.parse(line) as AuditEntry;
            if (!e || typeof e !== 'object' || typeof e.time !== 'string' || typeof e.type !== 'string')
              throw new Error();
            insert(e);
            count++;
          } catch {
            skipped++; // a torn last line (a crash while writing) or not ours
          }
        }
        mark.run(name, size, this.now());
      }
    })();
    for (const name of imported) {
      const file = path.join(this.dataDir, name);
      try {
        renameSync(file, `${file}.imported`);
      } catch (e) {
        this.log.warn('an imported audit file could not be renamed', { file, error: String(e) });
      }
    }
    if (count || skipped)
      this.log.info(`imported ${count} entries of the audit log files into the database`, {
        files: imported,
        skipped,
      });
  }

  private inserter(db: Db): (e: AuditEntry) => number {
    const st = db.prepare(
      'INSERT INTO audit (at, kind, type, result, user, on_behalf_of, machine, entry) VALUES (?, ?, ?, ?, ?, ?, ?, ?)',
    );
    return (e) => {
      const at = Date.parse(e.time);
      const kind = kindOf(e);
      if (kind === 'refusal') this.refusals++;
      return Number(
        st.run(
          Number.isNaN(at) ? this.now() : at,
          kind,
          e.type,
          e.result,
          e.user,
          e.onBehalfOf ?? null,
          e.machine ?? null,
          JSON.stringify(e),
        ).lastInsertRowid,
      );
    };
  }

  // ---------------------------------------------------------------- writing

  private write(entry: AuditInput): { entry: AuditEntry; id: number } {
    const { time, ...rest } = entry;
    const full = { time: time ?? new Date(this.now()).toISOString(), ...rest } as AuditEntry;
    const db = this.open();
    const id = this.inserter(db)(full);
    if (this.refusals > this.retention.refusalMax || this.now() - this.prunedAt > PRUNE_EVERY_MS)
      this.prune();
    if (this.closed) this.shut();
    return { entry: full, id };
  }

  /** Writes (commits) an entry; throws when it cannot. */
  append(entry: AuditInput): AuditEntry {
    return this.write(entry).entry;
  }

  /** A command's entry, committed before it is forwarded (`result: "pending"`); throws when it cannot. */
  begin(entry: Omit<AuditInput, 'result'>): { entry: AuditEntry; id: number } {
    return this.write({ ...entry, result: 'pending' });
  }

  /** The command's outcome, after its answer. */
  finish(id: number, entry: AuditEntry): void {
    const db = this.open();
    db.prepare('UPDATE audit SET result = ?, entry = ? WHERE id = ?').run(
      entry.result,
      JSON.stringify(entry),
      id,
    );
    if (this.closed) this.shut();
  }

  /** Deletes what is past its retention, and the oldest refusals beyond `refusalMax`. */
  prune(): number {
    const db = this.db;
    if (!db) return 0;
    const t = this.now();
    this.prunedAt = t;
    let n = 0;
    n += db
      .prepare("DELETE FROM audit WHERE kind = 'record' AND at < ?")
      .run(t - this.retention.recordDays * DAY_MS).changes;
    n += db
      .prepare("DELETE FROM audit WHERE kind = 'refusal' AND at < ?")
      .run(t - this.retention.refusalDays * DAY_MS).changes;
    const count = (
      db.prepare("SELECT COUNT(*) AS n FROM audit WHERE kind = 'refusal'").get() as { n: number }
    ).n;
    if (count > this.retention.refusalMax)
      n += db
        .prepare(
          "DELETE FROM audit WHERE id IN (SELECT id FROM audit WHERE kind = 'refusal' ORDER BY at, id LIMIT ?)",
        )
        .run(count - this.retention.refusalMax).changes;
    this.refusals = Math.min(count, this.retention.refusalMax);
    return n;
  }

  /** Kept for callers of the file log: every entry is committed when `append` returns. */
  flush(): Promise<void> {
    return Promise.resolve();
  }

  /** Shutdown: the database is closed. A later write opens it, writes and closes it again. */
  close(): Promise<void> {
    this.closed = true;
    this.shut();
    return Promise.resolve();
  }

  private shut(): void {
    const db = this.db;
    this.db = null;
    try {
      db?.close();
    } catch (e) {
      this.log.error('the audit log could not be closed', { file: this.file, error: String(e) });
    }
  }

  // ---------------------------------------------------------------- reading

  private read<T>(fn: (db: Db) => T): T {
    const db = this.open();
    try {
      return fn(db);
    } finally {
      if (this.closed) this.shut();
    }
  }

  /** Every entry, oldest first, synchronously: for tests and tools. */
  all(): AuditEntry[] {
    return this.read((db) =>
      (db.prepare('SELECT id, entry FROM audit ORDER BY at, id').all() as Row[]).map(parse),
    );
  }

  /** A page of the filtered entries, newest first, and how many match in all. */
  query(q: AuditQuery): Promise<{ entries: AuditEntry[]; total: number }> {
    const offset = Math.max(0, q.offset ?? 0);
    const limit = Math.min(1000, Math.max(1, q.limit ?? 50));
    const w = where(q);
    return Promise.resolve(
      this.read((db) => {
        const rows = db
          .prepare(`SELECT id, entry FROM audit ${w.sql} ORDER BY at DESC, id DESC LIMIT ? OFFSET ?`)
          .all(...w.args, limit, offset) as Row[];
        const total = (db.prepare(`SELECT COUNT(*) AS n FROM audit ${w.sql}`).get(...w.args) as { n: number })
          .n;
        return { entries: rows.map(parse), total };
      }),
    );
  }

  /** Every matching entry, newest first, a page at a time (each page one short read). */
  *pages(q: AuditQuery, size = CSV_PAGE): Generator<AuditEntry[]> {
    const w = where(q);
    let last: { at: number; id: number } | null = null;
    for (;;) {
      const after: { at: number; id: number } | null = last;
      const cond: string = after
        ? `${w.sql ? `${w.sql} AND` : 'WHERE'} (at < ? OR (at = ? AND id < ?))`
        : w.sql;
      const args: Array<string | number> = after ? [...w.args, after.at, after.at, after.id] : w.args;
      const rows: Array<Row & { at: number }> = this.read(
        (db) =>
          db
            .prepare(`SELECT id, at, entry FROM audit ${cond} ORDER BY at DESC, id DESC LIMIT ?`)
            .all(...args, size) as Array<Row & { at: number }>,
      );
      if (!rows.length) return;
      const end: (Row & { at: number }) | undefined = rows[rows.length - 1];
      if (end) last = { at: end.at, id: end.id };
      yield rows.map(parse);
      if (rows.length < size) return;
    }
  }

  /** Filtered, newest first: every matching entry. */
  filtered(q: AuditQuery): Promise<AuditEntry[]> {
    const out: AuditEntry[] = [];
    for (const p of this.pages(q)) out.push(...p);
    return Promise.resolve(out);
  }
}

// The HTTP side (query parameters, CSV export) lives in audit-csv.ts (which imports this module's
// types: not re-exported here, so the two make no import loop).
