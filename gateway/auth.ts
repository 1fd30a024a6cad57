import { randomBytes } from 'node:crypto';
import type { Role } from '../src/fleet/types';

/**
 * Console sessions (the HttpOnly cookie) and the brute-force limiter. In memory: a restart of
 * the gateway logs everyone out, which is the safe direction.
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
  token: string;
  user: string;
  /** Role at login: decides the idle timeout. */
  role: Role;
  createdAt: number;
  lastSeen: number;
  elevation: Elevation | null;
}

export class SessionStore {
  private sessions = new Map<string, ConsoleSession>();

  constructor(
    private readonly idle: IdleTimeouts,
    private readonly now: () => number,
  ) {}

  idleSeconds(role: Role): number {
    return this.idle[role];
  }

  create(user: string, role: Role): ConsoleSession {
    const t = this.now();
    this.prune(t);
    const s: ConsoleSession = {
      token: randomBytes(32).toString('base64url'),
      user,
      role,
      createdAt: t,
      lastSeen: t,
      elevation: null,
    };
    this.sessions.set(s.token, s);
    return s;
  }

  private prune(t: number): void {
    for (const [k, s] of this.sessions)
      if (t - s.lastSeen > this.idle[s.role] * 1000) this.sessions.delete(k);
  }

  /**
   * The live session for a token, touched (idle timer restarted) when `touch`. Returns
   * `{ expired }` for a session that timed out (and forgets it), null for an unknown token.
   */
  get(token: string | undefined, touch = true): ConsoleSession | { expired: ConsoleSession } | null {
    if (!token) return null;
    const s = this.sessions.get(token);
    if (!s) return null;
    const t = this.now();
    if (t - s.lastSeen > this.idle[s.role] * 1000) {
      this.sessions.delete(token);
      return { expired: s };
    }
    if (s.elevation && s.elevation.until <= t) s.elevation = null;
    if (touch) s.lastSeen = t;
    return s;
  }

  delete(token: string): void {
    this.sessions.delete(token);
  }

  /** Forget sessions of a user (removed from the users file). */
  dropUser(user: string): void {
    for (const [k, s] of this.sessions) if (s.user === user) this.sessions.delete(k);
  }
}

export interface RateLimitOptions {
  windowMs: number;
  perUser: number;
  perAddress: number;
}

export const DEFAULT_RATE_LIMIT: RateLimitOptions = { windowMs: 15 * 60_000, perUser: 5, perAddress: 20 };

/**
 * Failed attempts per key in a sliding window. A key with too many failures is blocked until
 * its oldest failure leaves the window. Keys: `user:<name>`, `addr:<address>`.
 */
export class FailureLimiter {
  private failures = new Map<string, number[]>();

  constructor(
    private readonly opts: RateLimitOptions,
    private readonly now: () => number,
  ) {}

  private recent(key: string): number[] {
    const t = this.now();
    const list = (this.failures.get(key) ?? []).filter((x) => t - x < this.opts.windowMs);
    if (list.length) this.failures.set(key, list);
    else this.failures.delete(key);
    return list;
  }

  private limitFor(key: string): number {
    return key.startsWith('addr:') ? this.opts.perAddress : this.opts.perUser;
  }

  /** Seconds to wait before another attempt, 0 when allowed. */
  retryAfter(keys: readonly string[]): number {
    let wait = 0;
    for (const k of keys) {
      const list = this.recent(k);
      if (list.length >= this.limitFor(k)) {
        const oldest = list[list.length - this.limitFor(k)] ?? list[0] ?? this.now();
        wait = Math.max(wait, Math.ceil((oldest + this.opts.windowMs - this.now()) / 1000));
      }
    }
    return wait;
  }

  fail(keys: readonly string[]): void {
    const t = this.now();
    if (this.failures.size > 10_000) {
      for (const [k, list] of this.failures)
        if (!list.some((x) => t - x < this.opts.windowMs)) this.failures.delete(k);
    }
    for (const k of keys) {
      const list = this.recent(k);
      list.push(t);
      this.failures.set(k, list);
    }
  }

  reset(key: string): void {
    this.failures.delete(key);
  }
}
