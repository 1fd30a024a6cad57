/**
 * The lock of a slider or numeric control on a touch screen (as Mainsail locks its sliders): while
 * locked the control ignores touch, so a glove brushing the screen changes nothing. A deliberate
 * tap on its lock unlocks it; it locks again by itself after `relockAfterMs` without use.
 */
export interface TouchLock {
  readonly locked: boolean;
  unlock(): void;
  lock(): void;
  /** The control was used while unlocked: the relock countdown starts again. */
  touch(): void;
  subscribe(listener: () => void): () => void;
  /** Stops the countdown and locks (the control is gone). */
  dispose(): void;
}

/** Unlocked and unused this long, a control locks again. */
export const RELOCK_AFTER_MS = 10_000;

export function createTouchLock(relockAfterMs: number | null = RELOCK_AFTER_MS): TouchLock {
  let locked = true;
  let timer: ReturnType<typeof setTimeout> | null = null;
  const listeners = new Set<() => void>();

  const set = (next: boolean) => {
    if (next === locked) return;
    locked = next;
    for (const l of [...listeners]) l();
  };
  const stopTimer = () => {
    if (timer !== null) clearTimeout(timer);
    timer = null;
  };
  const arm = () => {
    stopTimer();
    if (relockAfterMs === null || locked) return;
    timer = setTimeout(() => {
      timer = null;
      set(true);
    }, relockAfterMs);
  };

  return {
    get locked() {
      return locked;
    },
    unlock() {
      set(false);
      arm();
    },
    lock() {
      stopTimer();
      set(true);
    },
    touch() {
      if (!locked) arm();
    },
    subscribe(listener) {
      listeners.add(listener);
      return () => listeners.delete(listener);
    },
    dispose() {
      stopTimer();
      locked = true;
    },
  };
}
