import { closeSync, mkdirSync, openSync } from 'node:fs';
import { dirname } from 'node:path';
import Database from 'better-sqlite3';

/**
 * The history database (`<data folder>/history.sqlite`): opened, configured and migrated by the
 * server itself. Nothing to install: SQLite is compiled into the `better-sqlite3` binding.
 *
 * - WAL journal: readers (the API) never block the recorder, and a crash mid-write leaves the last
 *   committed state (a transaction is in the file whole or not at all).
 * - `synchronous=NORMAL`: a commit does not wait for an fsync. better-sqlite3 is synchronous, on
 *   the gateway's one thread: with FULL, every state change and every heartbeat would stall the
 *   proxying of machine commands for an fsync (tens of ms on a shop PC's SD card or eMMC). In WAL
 *   mode NORMAL never corrupts the file; a process crash loses nothing committed; a power cut can
 *   lose the commits since the last checkpoint, and the store checkpoints every minute
 *   (`CHECKPOINT_EVERY_MS` in recorder.ts), so at most about a minute of history.
 * - Versioned migrations: `PRAGMA user_version` is the number of migrations applied; each one
 *   runs in its own transaction together with the version bump, so a file is always at exactly
 *   one version. A file from a newer Shopdeck (a higher version) is refused, never changed.
 */

export type Db = Database.Database;

export interface Migration {
  /** What it changes, for the log. */
  name: string;
  sql: string;
}

/** In order; never edit one that shipped: add the next. Times are ms since the epoch (UTC). */
export const MIGRATIONS: readonly Migration[] = [
  {
    name: 'jobs, state intervals, last seen',
    sql: `
      CREATE TABLE jobs (
        id INTEGER PRIMARY KEY,
        machine TEXT NOT NULL,
        family TEXT NOT NULL,
        name TEXT,
        started_at INTEGER NOT NULL,
        ended_at INTEGER,
        outcome TEXT CHECK (outcome IN ('finished', 'cancelled', 'failed', 'unknown')),
        running_ms INTEGER NOT NULL DEFAULT 0,
        paused_ms INTEGER NOT NULL DEFAULT 0,
        counted_to INTEGER NOT NULL,
        progress REAL,
        started_by TEXT,
        paused_by TEXT,
        resumed_by TEXT,
        stopped_by TEXT,
        end_alarm TEXT,
        CHECK ((ended_at IS NULL) = (outcome IS NULL))
      );
      CREATE INDEX jobs_started ON jobs (started_at);
      CREATE INDEX jobs_machine_started ON jobs (machine, started_at);
      CREATE INDEX jobs_ended ON jobs (ended_at);

      CREATE TABLE states (
        id INTEGER PRIMARY KEY,
        machine TEXT NOT NULL,
        state TEXT NOT NULL CHECK (state IN ('running', 'paused', 'idle', 'alarm', 'offline', 'unknown')),
        alarm TEXT,
        started_at INTEGER NOT NULL,
        ended_at INTEGER,
        CHECK (ended_at IS NULL OR ended_at >= started_at)
      );
      CREATE INDEX states_machine_started ON states (machine, started_at);
      CREATE INDEX states_started ON states (started_at);
      CREATE INDEX states_ended ON states (ended_at);

      CREATE TABLE last_seen (
        machine TEXT PRIMARY KEY,
        at INTEGER NOT NULL
      );
    `,
  },
  {
    name: 'daily statistics kept by the controllers (touchcut_days)',
    sql: `
      CREATE TABLE touchcut_days (
        machine TEXT NOT NULL,
        day TEXT NOT NULL CHECK (day GLOB '[0-9][0-9][0-9][0-9]-[0-9][0-9]-[0-9][0-9]'),
        pulled_at INTEGER NOT NULL,
        stats TEXT NOT NULL CHECK (json_valid(stats)),
        PRIMARY KEY (machine, day)
      );
      CREATE INDEX touchcut_days_day ON touchcut_days (day);
    `,
  },
  {
    // The audit log (gateway/audit.ts): each entry as JSON, with the columns it is filtered by.
    // `kind`: 'record' (commands, logins, changes; kept long) or 'refusal' (kept short, bounded).
    name: 'audit log',
    sql: `
      CREATE TABLE audit (
        id INTEGER PRIMARY KEY,
        at INTEGER NOT NULL,
        kind TEXT NOT NULL CHECK (kind IN ('record', 'refusal')),
        type TEXT NOT NULL,
        result TEXT NOT NULL,
        user TEXT NOT NULL,
        on_behalf_of TEXT,
        machine TEXT,
        entry TEXT NOT NULL CHECK (json_valid(entry))
      );
      CREATE INDEX audit_at ON audit (at);
      CREATE INDEX audit_machine_at ON audit (machine, at);
      CREATE INDEX audit_user_at ON audit (user, at);
      CREATE INDEX audit_on_behalf_of_at ON audit (on_behalf_of, at);
      CREATE INDEX audit_kind_at ON audit (kind, at);

      CREATE TABLE audit_imports (
        file TEXT NOT NULL,
        size INTEGER NOT NULL,
        at INTEGER NOT NULL,
        PRIMARY KEY (file, size)
      );
    `,
  },
  {
    // Console sessions (gateway/auth.ts), kept across restarts: the SHA-256 of the token, never
    // the token; ended (deleted) by logout, idle timeout and removal of the user.
    name: 'console sessions',
    sql: `
      CREATE TABLE sessions (
        id TEXT PRIMARY KEY CHECK (length(id) = 64),
        user TEXT NOT NULL,
        role TEXT NOT NULL CHECK (role IN ('viewer', 'operator', 'supervisor')),
        created_at INTEGER NOT NULL,
        last_seen INTEGER NOT NULL
      );
      CREATE INDEX sessions_user ON sessions (user);
    `,
  },
];

export class NewerSchemaError extends Error {}

export function schemaVersion(db: Db): number {
  return Number(db.pragma('user_version', { simple: true }));
}

/** Applies the migrations after the file's version, each in a transaction. Returns the names applied. */
export function migrate(db: Db, migrations: readonly Migration[] = MIGRATIONS): string[] {
  const have = schemaVersion(db);
  if (have > migrations.length)
    throw new NewerSchemaError(
      `the history file is at schema version ${have}, newer than this Shopdeck knows (${migrations.length}): left as it is`,
    );
  const applied: string[] = [];
  for (let v = have; v < migrations.length; v++) {
    const m = migrations[v];
    if (!m) break;
    const ran = db
      .transaction(() => {
        // Another process (a second `npm run user`, the server starting) may have opened the same
        // file at the same time and applied this migration between our read of the version and
        // this write lock: the version is read again under the lock, and a migration already
        // applied is not run twice.
        if (schemaVersion(db) !== v) return false;
        db.exec(m.sql);
        // user_version is written in the same transaction: a migration is applied whole or not at all.
        db.pragma(`user_version = ${v + 1}`);
        return true;
      })
      .immediate();
    if (ran) applied.push(m.name);
  }
  return applied;
}

/** Opens (creating the folder and the file if needed), configures and migrates. */
export function openHistoryDb(
  file: string,
  migrations: readonly Migration[] = MIGRATIONS,
): { db: Db; applied: string[] } {
  mkdirSync(dirname(file), { recursive: true });
  // Readable by the server's user only, as the audit log (SQLite gives its WAL the same mode).
  closeSync(openSync(file, 'a', 0o600));
  const db = new Database(file);
  try {
    // Another connection (a person with the sqlite3 shell, a second process opening the file at
    // the same moment) holding a lock: wait, not fail. Set first: switching to WAL takes a lock.
    db.pragma('busy_timeout = 5000');
    db.pragma('journal_mode = WAL');
    db.pragma('synchronous = NORMAL');
    db.pragma('foreign_keys = ON');
    const applied = migrate(db, migrations);
    return { db, applied };
  } catch (e) {
    db.close();
    throw e;
  }
}
