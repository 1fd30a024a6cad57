import { createStore } from 'zustand/vanilla';
import { backoffDelay } from '../../fleet/link';

/**
 * Whether the console's own server answers. At boot the page needs `/api/session` and
 * `/api/machines`; when they fail before any HTTP answer (no network, server down, an installed
 * app started offline), the page says "Console unreachable — retrying" and tries again, backing
 * off (about 1 s to 30 s), at once when the browser is back online or on "Try now". Only reads
 * go through here: a command is never retried.
 */
export interface ReachState {
  unreachable: boolean;
  /** The browser says it has no network at all (navigator.onLine). */
  offline: boolean;
  /** When the next try starts (ms), while unreachable. */
  nextTryAt: number | null;
}

export const reachStore = createStore<ReachState>(() => ({
  unreachable: false,
  offline: false,
  nextTryAt: null,
}));

/** fetch() rejects with a TypeError when no HTTP answer came (an HTTP error status resolves). */
export function isNetworkFailure(e: unknown): boolean {
  return e instanceof TypeError;
}

const waiting = new Set<() => void>();

/** Ends the current wait: the next try starts now. */
export function retryNow(): void {
  for (const wake of [...waiting]) wake();
}

function pause(ms: number): Promise<void> {
  return new Promise((resolve) => {
    const wake = (): void => {
      clearTimeout(timer);
      waiting.delete(wake);
      if (typeof window !== 'undefined') window.removeEventListener('online', wake);
      resolve();
    };
    const timer = setTimeout(wake, ms);
    waiting.add(wake);
    if (typeof window !== 'undefined') window.addEventListener('online', wake);
  });
}

function browserOffline(): boolean {
  return typeof navigator !== 'undefined' && navigator.onLine === false;
}

/**
 * Runs `read` until it gets an answer from the server: a network failure waits and tries again
 * (and shows the unreachable state); any other outcome, value or error, is returned as it is.
 */
export async function untilReachable<T>(
  read: () => Promise<T>,
  delayOf: (attempt: number) => number = backoffDelay,
): Promise<T> {
  for (let attempt = 0; ; attempt++) {
    try {
      const value = await read();
      reached();
      return value;
    } catch (e) {
      if (!isNetworkFailure(e)) {
        reached();
        throw e;
      }
      const wait = delayOf(attempt);
      reachStore.setState({ unreachable: true, offline: browserOffline(), nextTryAt: Date.now() + wait });
      await pause(wait);
    }
  }
}

function reached(): void {
  if (reachStore.getState().unreachable)
    reachStore.setState({ unreachable: false, offline: false, nextTryAt: null });
}
