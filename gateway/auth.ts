import { createHash, randomBytes } from 'node:crypto';
import type { Role } from '../src/fleet/types';
import { openHistoryDb, type Db } from './history/db';

/**
 * Console sessions (the HttpOnly cookie), the brute-force limiter and the addresses users log
 * in from. Sessions are kept across a restart of the server (`SessionStore` with a
 * `SqliteSessionFile`: the `sessions` table of `<data>/history.sqlite`, holding the SHA-256 of
 * each token, never the token), with the same idle timeouts; a PIN elevation is not kept (a
 * restart ends it). The limiter and the login history are in memory.
 */

export const SESSION_COOKIE = 'shopdeck_session';

export interface IdleTimeouts {
  viewer: number;
  operator: number;
  supervisor: number;
}

/** Seconds. Operators on a tablet: a shift; supervisors: an hour. */
export const DEFAULT_IDLE: IdleTimeouts = { viewer: 12 * 3600, operator: 12 * 3600, supervisor: 3600 };
export const DEFAULT_ELEVATION_S = 5 * 60;

export interface Elevation {
  /** The supervisor whose PIN unlocked the tablet. */
  supervisor: string;
  /** ms since epoch */
  until: number;
}

export interface ConsoleSession {
  /**
   * The cookie's value. Known in memory only: a session loaded from the file after a restart
   * has '' here until its browser presents the token again (`get`).
   */
  token: string;
  /** SHA-256 (hex) of the token: the session's key, the only form of the token stored. */
  id: string;
  user: string;
  /**
   * The user's role as last seen: set at login, updated when the users file changes (`who()` in
   * context.ts); decides the idle timeout.
   */
  role: Role;
  createdAt: number;
  lastSeen: number;
  elevation: Elevation | null;
}

/** What a session file holds of a session: never the token, never an elevation. */
export interface StoredSession {
  id: string;
  user: string;
  role: Role;
  createdAt: number;
  lastSeen: number;
}

/** Where sessions are kept across restarts. Every call may throw (the store then goes on in memory). */
export interface SessionFile {
  load(): StoredSession[];
  put(s: StoredSession): void;
  remove(id: string): void;
  close(): void;
}

export function tokenHash(token: string): string {
  return createHash('sha256').update(token, 'utf8').digest('hex');
}

const ROLES: ReadonlySet<string> = new Set(['viewer', 'operator', 'supervisor']);

/**
 * The `sessions` table of the history database (migration 4 in history/db.ts), on a connection
 * of its own with `synchronous=FULL`: a logout is on disk before it is answered.
 */
export class SqliteSessionFile implements SessionFile {
  private db: Db | null = null;

  constructor(readonly file: string) {}

  private open(): Db {
    if (!this.db) {
      const db = openHistoryDb(this.file).db;
      db.pragma('synchronous = FULL');
      this.db = db;
    }
    return this.db;
  }

  load(): StoredSession[] {
    const rows = this.open()
      .prepare('SELECT id, user, role, created_at AS createdAt, last_seen AS lastSeen FROM sessions')
      .all() as Array<Record<string, unknown>>;
    const out: StoredSession[] = [];
    for (const r of rows)
      if (
        typeof r.id === 'string' &&
        typeof r.user === 'string' &&
        typeof r.role === 'string' &&
        ROLES.has(r.role) &&
        typeof r.createdAt === 'number' &&
        typeof r.lastSeen === 'number'
      )
        out.push({
          id: r.id,
          user: r.user,
          role: r.role as Role,
          createdAt: r.createdAt,
          lastSeen: r.lastSeen,
        });
    return out;
  }

  put(s: StoredSession): void {
    this.open()
      .prepare(
        `INSERT INTO sessions (id, user, role, created_at, last_seen) VALUES (?, ?, ?, ?, ?)
         ON CONFLICT (id) DO UPDATE SET user = excluded.user, role = excluded.role, last_seen = excluded.last_seen`,
      )
      .run(s.id, s.user, s.role, s.createdAt, s.lastSeen);
  }

  remove(id: string): void {
    this.open().prepare('DELETE FROM sessions WHERE id = ?').run(id);
  }

  close(): void {
    this.db?.close();
    this.db = null;
  }
}

/**
 * A session's last activity is written at most this often (ms): after a restart a session may
 * look up to this much older than it is, so it can only end sooner, never later.
 */
export const SESSION_TOUCH_WRITE_MS = 60_000;

export class SessionStore {
  private sessions = new Map<string, ConsoleSession>();
  private loaded = false;
  /** lastSeen as last written, per session id. */
  private written = new Map<string, number>();

  constructor(
    private readonly idle: IdleTimeouts,
    private readonly now: () => number,
    private readonly file: SessionFile | null = null,
    private readonly onFileError: (e: unknown) => void = () => {},
  ) {}

  idleSeconds(role: Role): number {
    return this.idle[role];
  }

  /** Sessions ended while the file could not be written: deleted at the next write that works. */
  private unremoved = new Set<string>();

  private write(what: (f: SessionFile) => void): void {
    if (!this.file) return;
    try {
      for (const id of this.unremoved) {
        this.file.remove(id);
        this.unremoved.delete(id);
      }
      what(this.file);
    } catch (e) {
      this.onFileError(e);
    }
  }

  /** The kept sessions, read once (the expired ones deleted from the file). */
  private load(): void {
    if (this.loaded) return;
    this.loaded = true;
    if (!this.file) return;
    let rows: StoredSession[];
    try {
      rows = this.file.load();
    } catch (e) {
      this.onFileError(e);
      return;
    }
    const t = this.now();
    for (const r of rows) {
      if (t - r.lastSeen > this.idle[r.role] * 1000 || this.sessions.has(r.id)) {
        this.write((f) => f.remove(r.id));
        continue;
      }
      this.sessions.set(r.id, { token: '', elevation: null, ...r });
      this.written.set(r.id, r.lastSeen);
    }
  }

  private stored(s: ConsoleSession): StoredSession {
    return { id: s.id, user: s.user, role: s.role, createdAt: s.createdAt, lastSeen: s.lastSeen };
  }

  create(user: string, role: Role): ConsoleSession {
    this.load();
    const t = this.now();
    this.prune(t);
    const token = randomBytes(32).toString('base64url');
    const s: ConsoleSession = {
      token,
      id: tokenHash(token),
      user,
      role,
      createdAt: t,
      lastSeen: t,
      elevation: null,
    };
    this.sessions.set(s.id, s);
    this.written.set(s.id, t);
    this.write((f) => f.put(this.stored(s)));
    return s;
  }

  private forget(id: string): void {
    this.sessions.delete(id);
    this.written.delete(id);
    this.unremoved.add(id);
    this.write((f) => {
      f.remove(id);
      this.unremoved.delete(id);
    });
  }

  private prune(t: number): void {
    for (const [k, s] of this.sessions) if (t - s.lastSeen > this.idle[s.role] * 1000) this.forget(k);
  }

  /**
   * The live session for a token, touched (idle timer restarted) when `touch`. Returns
   * `{ expired }` for a session that timed out (and forgets it), null for an unknown token.
   */
  get(token: string | undefined, touch = true): ConsoleSession | { expired: ConsoleSession } | null {
    if (!token) return null;
    this.load();
    const id = tokenHash(token);
    const s = this.sessions.get(id);
    if (!s) return null;
    const t = this.now();
    if (t - s.lastSeen > this.idle[s.role] * 1000) {
      this.forget(id);
      return { expired: s };
    }
    if (!s.token) s.token = token;
    if (s.elevation && s.elevation.until <= t) s.elevation = null;
    if (touch) {
      s.lastSeen = t;
      if (t - (this.written.get(id) ?? 0) >= SESSION_TOUCH_WRITE_MS) {
        this.written.set(id, t);
        this.write((f) => f.put(this.stored(s)));
      }
    }
    return s;
  }

  /** Writes a session's role after it changed (`who()` in context.ts follows the users file). */
  save(s: ConsoleSession): void {
    if (this.sessions.get(s.id) === s) this.write((f) => f.put(this.stored(s)));
  }

  /** Every session, expired ones not yet pruned included. */
  list(): ConsoleSession[] {
    this.load();
    return [...this.sessions.values()];
  }

  delete(token: string): void {
    this.load();
    this.forget(tokenHash(token));
  }

  /** Forget sessions of a user (removed from the users file); how many there were. */
  dropUser(user: string): number {
    this.load();
    let n = 0;
    for (const [k, s] of this.sessions)
      if (s.user === user) {
        this.forget(k);
        n++;
      }
    return n;
  }

  close(): void {
    this.write((f) => f.close());
  }
}

export interface RateLimitOptions {
  windowMs: number;
  /** Failed logins per (user, address). */
  perUser: number;
  /** Failed logins and PINs per address, whichever the user. */
  perAddress: number;
  /**
   * Wrong PINs per tablet (the operator's session that tried, at its address), whichever the
   * supervisor: then that tablet may try no more PINs. Never locks a supervisor's PIN for others.
   */
  perPin: number;
  /** Wrong PINs per operator account, from any address (an operator moving between tablets). */
  perPinOperator: number;
  /**
   * Backstop against guessing one supervisor's PIN from many operators or addresses: wrong PINs
   * for that supervisor, from anywhere, enforced only on tablets the supervisor has never
   * unlocked (`LoginHistory` of (operator, address) pairs), so that the tablets the supervisor
   * uses keep working, and never for the supervisor's password login.
   */
  perPinTotal: number;
  /**
   * Backstop against guessing one password from many addresses: failed logins per user, counted
   * and enforced only for addresses the user has not logged in from (`LoginHistory`), so that an
   * attacker cannot lock the real user out of their own tablet. Much higher than `perUser`: it
   * only has to cap a distributed guesser (5 per address) at some hundred guesses per window.
   */
  perUserTotal: number;
}

export const DEFAULT_RATE_LIMIT: RateLimitOptions = {
  windowMs: 15 * 60_000,
  perUser: 5,
  perAddress: 20,
  perPin: 5,
  perPinOperator: 10,
  perPinTotal: 30,
  perUserTotal: 100,
};

/** A counter the limiter keeps: `key` may have at most `limit` attempts in `windowMs`. */
export interface LimitKey {
  key: string;
  limit: number;
  /** Default: the limiter's `windowMs`. */
  windowMs?: number;
}

export type Reservation =
  | {
      ok: true;
      /** The attempt succeeded: give its slot back on every key (once). */
      release(): void;
    }
  | { ok: false; retryAfterS: number; key: string };

/**
 * Attempts per key in a sliding window. An attempt is counted BEFORE it is evaluated
 * (`reserve`, synchronous: concurrent requests cannot all pass the check while the slow hash of
 * the first ones runs) and given back only when it succeeded (`release`). A key at its limit is
 * blocked until its oldest attempt leaves the window.
 */
export class FailureLimiter {
  private hits = new Map<string, { windowMs: number; times: number[] }>();

  constructor(
    readonly opts: RateLimitOptions,
    private readonly now: () => number,
  ) {}

  private recent(k: LimitKey, t: number): number[] {
    const windowMs = k.windowMs ?? this.opts.windowMs;
    const entry = this.hits.get(k.key);
    if (!entry) return [];
    entry.times = entry.times.filter((x) => t - x < windowMs);
    if (!entry.times.length) this.hits.delete(k.key);
    return entry.times;
  }

  /** Seconds until `k` allows another attempt, 0 when it does. */
  private waitFor(k: LimitKey, t: number): number {
    const list = this.recent(k, t);
    if (list.length < k.limit) return 0;
    const oldest = list[list.length - k.limit] ?? t;
    return Math.max(1, Math.ceil((oldest + (k.windowMs ?? this.opts.windowMs) - t) / 1000));
  }

  /** Counts one attempt on every key, or none when one of them is at its limit. */
  reserve(keys: readonly LimitKey[]): Reservation {
    const t = this.now();
    this.sweep(t);
    let wait = 0;
    let blocked = '';
    for (const k of keys) {
      const w = this.waitFor(k, t);
      if (w > wait) {
        wait = w;
        blocked = k.key;
      }
    }
    if (wait > 0) return { ok: false, retryAfterS: wait, key: blocked };
    for (const k of keys) {
      const entry = this.hits.get(k.key);
      if (entry) entry.times.push(t);
      else this.hits.set(k.key, { windowMs: k.windowMs ?? this.opts.windowMs, times: [t] });
    }
    let released = false;
    return {
      ok: true,
      release: () => {
        if (released) return;
        released = true;
        for (const k of keys) {
          const entry = this.hits.get(k.key);
          const i = entry ? entry.times.lastIndexOf(t) : -1;
          if (entry && i >= 0) entry.times.splice(i, 1);
          if (entry && !entry.times.length) this.hits.delete(k.key);
        }
      },
    };
  }

  /** Attempts counted on `k` in its window. */
  count(k: LimitKey): number {
    return this.recent(k, this.now()).length;
  }

  /** Forgets a key's attempts. */
  clear(key: string): void {
    this.hits.delete(key);
  }

  private sweep(t: number): void {
    if (this.hits.size <= 10_000) return;
    for (const [key, e] of this.hits) if (!e.times.some((x) => t - x < e.windowMs)) this.hits.delete(key);
  }
}

/**
 * Addresses each user logged in from successfully (the last 20, for 30 days): the per-user
 * backstop of the limiter spares them, so that a guesser elsewhere cannot lock the user out of
 * the tablet they use.
 */
export class LoginHistory {
  private byUser = new Map<string, Map<string, number>>();

  constructor(
    private readonly now: () => number,
    private readonly keepMs = 30 * 24 * 3600_000,
    private readonly perUser = 20,
  ) {}

  remember(user: string, address: string): void {
    const m = this.byUser.get(user) ?? new Map<string, number>();
    m.delete(address);
    m.set(address, this.now());
    while (m.size > this.perUser) {
      const first = m.keys().next();
      if (first.done) break;
      m.delete(first.value);
    }
    this.byUser.set(user, m);
  }

  knows(user: string, address: string): boolean {
    const at = this.byUser.get(user)?.get(address);
    return at !== undefined && this.now() - at < this.keepMs;
  }

  forget(user: string): void {
    this.byUser.delete(user);
  }
}
