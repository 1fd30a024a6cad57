import { useEffect, useState, useSyncExternalStore } from 'react';

/**
 * Keeps a kiosk tablet's screen on while a job runs (Screen Wake Lock API). The browser drops the
 * lock whenever the page is hidden; it is asked for again when the page shows, released when the
 * job ends or the page goes. Only in a secure context (HTTPS, or localhost).
 */

export type WakeStatus =
  /** The browser has no Screen Wake Lock. */
  | 'unsupported'
  /** Not a secure context (plain HTTP to another host): the API is not offered. */
  | 'insecure'
  /** Not wanted (no job running). */
  | 'off'
  /** Wanted, waiting: the page is hidden or the request is under way. */
  | 'waiting'
  | 'held'
  /** The browser refused (power saving, permissions policy); asked again later. */
  | 'refused';

/** The parts of `WakeLockSentinel` used here. */
export interface SentinelLike {
  readonly released: boolean;
  release(): Promise<void>;
  addEventListener(type: 'release', fn: () => void): void;
  removeEventListener(type: 'release', fn: () => void): void;
}

export interface WakeEnv {
  wakeLock: { request(type: 'screen'): Promise<SentinelLike> } | undefined;
  secure: boolean;
  doc: {
    readonly visibilityState: DocumentVisibilityState;
    addEventListener(type: 'visibilitychange', fn: () => void): void;
    removeEventListener(type: 'visibilitychange', fn: () => void): void;
  };
}

/** A refused request is tried again this often while the lock is wanted and the page shows. */
export const WAKE_RETRY_MS = 30_000;

export function browserWakeEnv(): WakeEnv {
  const nav = navigator as Navigator & { wakeLock?: WakeEnv['wakeLock'] };
  return { wakeLock: nav.wakeLock, secure: window.isSecureContext, doc: document };
}

export class ScreenWakeLock {
  private wanted = false;
  private started = false;
  private sentinel: SentinelLike | null = null;
  private pending = false;
  private retry: ReturnType<typeof setTimeout> | null = null;
  private current: WakeStatus;
  private readonly listeners = new Set<() => void>();

  constructor(private readonly env: WakeEnv) {
    this.current = !env.secure ? 'insecure' : env.wakeLock ? 'off' : 'unsupported';
  }

  /** The page shows: follow its visibility (call `want` after). */
  start(): void {
    if (this.started) return;
    this.started = true;
    this.env.doc.addEventListener('visibilitychange', this.onVisibility);
  }

  /** The page goes: the lock is released and nothing is asked for until `start` again. */
  stop(): void {
    this.want(false);
    this.started = false;
    this.env.doc.removeEventListener('visibilitychange', this.onVisibility);
  }

  get status(): WakeStatus {
    return this.current;
  }

  subscribe = (fn: () => void): (() => void) => {
    this.listeners.add(fn);
    return () => this.listeners.delete(fn);
  };

  /** Whether the screen should stay on (a job runs). Ignored unless started. */
  want(on: boolean): void {
    if ((on && !this.started) || on === this.wanted) return;
    this.wanted = on;
    if (on) this.acquire();
    else this.drop('off');
  }

  private usable(): boolean {
    return this.env.secure && this.env.wakeLock !== undefined;
  }

  private set(s: WakeStatus): void {
    if (!this.usable() || s === this.current) return;
    this.current = s;
    for (const l of [...this.listeners]) l();
  }

  private readonly onVisibility = (): void => {
    if (this.wanted && this.env.doc.visibilityState === 'visible') this.acquire();
  };

  private readonly onRelease = (): void => {
    // The browser let go (page hidden, system): ask again as soon as the page shows.
    this.sentinel?.removeEventListener('release', this.onRelease);
    this.sentinel = null;
    if (!this.wanted) return;
    this.set('waiting');
    this.onVisibility();
  };

  private acquire(): void {
    const api = this.env.wakeLock;
    if (!this.usable() || !api || !this.wanted || !this.started) return;
    if (this.pending || (this.sentinel && !this.sentinel.released)) return;
    this.clearRetry();
    if (this.env.doc.visibilityState !== 'visible') {
      this.set('waiting');
      return;
    }
    this.pending = true;
    this.set('waiting');
    api.request('screen').then(
      (s) => {
        this.pending = false;
        if (!this.wanted) {
          void s.release().catch(() => undefined);
          return;
        }
        this.sentinel = s;
        s.addEventListener('release', this.onRelease);
        this.set('held');
      },
      () => {
        this.pending = false;
        if (!this.wanted) return;
        this.set('refused');
        this.retry = setTimeout(() => {
          this.retry = null;
          this.acquire();
        }, WAKE_RETRY_MS);
      },
    );
  }

  private clearRetry(): void {
    if (this.retry !== null) clearTimeout(this.retry);
    this.retry = null;
  }

  private drop(status: WakeStatus): void {
    this.clearRetry();
    const s = this.sentinel;
    this.sentinel = null;
    if (s) {
      s.removeEventListener('release', this.onRelease);
      void s.release().catch(() => undefined);
    }
    this.set(status);
  }
}

/** Keeps the screen on while `wanted` and the page is shown; released when the page goes. */
export function useScreenWakeLock(wanted: boolean): WakeStatus {
  const [lock] = useState(() => new ScreenWakeLock(browserWakeEnv()));
  useEffect(() => {
    lock.start();
    return () => lock.stop();
  }, [lock]);
  useEffect(() => lock.want(wanted), [lock, wanted]);
  return useSyncExternalStore(lock.subscribe, () => lock.status);
}
