import type { AuditEntry } from './audit';

/** Refusals limited where they are made, so that nobody can fill the audit log with them. */

export interface RefusalLimit {
  windowMs: number;
  /** Entries per user (or per address, without a session) written in a window; the rest are counted into one summary. */
  firstN: number;
}

export const REFUSAL_LIMIT: RefusalLimit = { windowMs: 60_000, firstN: 10 };

type AuditRecord = Omit<AuditEntry, 'time'>;

/**
 * What a client can make the gateway write as often as it likes: refusals (of anyone: a signed-in
 * viewer's forged commands as much as a client without a session) and attempts the login/PIN
 * limiter refused.
 */
function floodable(e: AuditRecord): boolean {
  if (e.type === 'refused') return true;
  return (e.type === 'login-failed' || e.type === 'elevate-failed') && e.result === 'refused';
}

interface RefusalWindow {
  start: number;
  written: number;
  more: number;
  user: string;
  address: string;
  machines: Set<string>;
}

/**
 * Keeps refusals from filling the audit log: per signed-in user (`user: "nobody"`, no session:
 * per address), the first `firstN` in a window are written, the rest counted and written as ONE
 * entry ("37 more refused requests by vic (from 10.0.0.9) in the last minute", timed at the
 * window's end) when the window ends: on the next record (`admit`) or from an unref'd timer,
 * whichever comes first. Everything else passes. (Refusals are also kept apart from commands in
 * the audit table, audit.ts: they never push a command out.)
 */
export class RefusalAggregator {
  private windows = new Map<string, RefusalWindow>();
  private timer: NodeJS.Timeout | null = null;

  constructor(
    private readonly limit: RefusalLimit,
    private readonly now: () => number,
    private readonly write: (e: AuditRecord & { time: string }) => void,
  ) {}

  /** True: write `e` now. False: it was counted into its user's (or address's) summary. */
  admit(e: AuditRecord): boolean {
    const t = this.now();
    this.flush(t);
    if (!floodable(e)) return true;
    const address = e.address ?? 'unknown';
    const user = e.user || 'nobody';
    const key = user === 'nobody' ? `address ${address}` : `user ${user}`;
    let w = this.windows.get(key);
    if (!w) {
      if (this.windows.size >= 10_000) this.flush(Number.POSITIVE_INFINITY);
      w = { start: t, written: 0, more: 0, user, address, machines: new Set() };
      this.windows.set(key, w);
    }
    if (w.written < this.limit.firstN) {
      w.written++;
      return true;
    }
    w.more++;
    w.address = address;
    if (e.machine && w.machines.size < 5) w.machines.add(e.machine);
    this.arm();
    return false;
  }

  /** Writes the summaries of the windows that ended by `t` (every window: `Infinity`). */
  flush(t: number = this.now()): void {
    for (const [key, w] of this.windows) {
      const end = w.start + this.limit.windowMs;
      if (end > t) continue;
      this.windows.delete(key);
      if (!w.more) continue;
      const span = this.limit.windowMs === 60_000 ? 'minute' : `${Math.round(this.limit.windowMs / 1000)} s`;
      const by = w.user === 'nobody' ? `from ${w.address}` : `by ${w.user} (from ${w.address})`;
      const on = w.user !== 'nobody' && w.machines.size ? ` (machines: ${[...w.machines].join(', ')})` : '';
      this.write({
        type: 'refused',
        result: 'refused',
        user: w.user,
        source: 'gateway',
        address: w.address,
        detail: `${w.more} more refused requests ${by} in the last ${span}${on}`,
        time: new Date(Math.min(end, this.now())).toISOString(),
      });
    }
  }

  /** Writes every pending summary and stops the timer (the gateway closes). */
  dispose(): void {
    if (this.timer) clearTimeout(this.timer);
    this.timer = null;
    this.flush(Number.POSITIVE_INFINITY);
  }

  private arm(): void {
    if (this.timer) return;
    this.timer = setTimeout(() => {
      this.timer = null;
      this.flush();
      if ([...this.windows.values()].some((w) => w.more > 0)) this.arm();
    }, this.limit.windowMs);
    this.timer.unref();
  }
}
