import { useSyncExternalStore } from 'react';

/**
 * Whether an emergency stop (and a family's own big STOP) asks first on this console: a setting
 * per console, kept in this browser's localStorage (`on` or `off`); unset, it follows the screen:
 * on for touch screens, where the brush of a glove is a tap. The job control row
 * (src/app/kiosk/JobControls.tsx), the Duet's message box and g2core's jog STOP all read it here;
 * the top bar's menu changes it.
 */
export const ESTOP_CONFIRM_KEY = 'shopdeck.estop-confirm';

/** A touch screen (also one beside a mouse: a tablet with a keyboard case). */
const COARSE = '(pointer: coarse), (any-pointer: coarse)';

/** The question an emergency stop asks first. */
export const ESTOP_QUESTION =
  'Emergency stop: halt the machine now? Motion and heaters stop at once and the job ends; it cannot be resumed.';

/** What is said on screen after an emergency stop was sent. */
export const ESTOP_SAID =
  'Emergency stop sent: the machine is halted and the job has ended. Check the machine before the next job.';

const listeners = new Set<() => void>();

function coarse(): boolean {
  return (
    typeof window !== 'undefined' &&
    typeof window.matchMedia === 'function' &&
    window.matchMedia(COARSE).matches
  );
}

function stored(): 'on' | 'off' | null {
  if (typeof window === 'undefined') return null;
  try {
    const v = window.localStorage.getItem(ESTOP_CONFIRM_KEY);
    return v === 'on' || v === 'off' ? v : null;
  } catch {
    // Storage refused (private mode): the screen's default.
    return null;
  }
}

/** The setting now: this console's choice, else on for a touch screen. */
export function estopConfirmNow(): boolean {
  const set = stored();
  return set === null ? coarse() : set === 'on';
}

/** What an unset console does: ask on a touch screen. */
export function estopConfirmDefault(): boolean {
  return coarse();
}

/** Sets this console's choice (null: back to the screen's default); every control follows at once. */
export function setEstopConfirm(on: boolean | null): void {
  try {
    if (on === null) window.localStorage.removeItem(ESTOP_CONFIRM_KEY);
    else window.localStorage.setItem(ESTOP_CONFIRM_KEY, on ? 'on' : 'off');
  } catch {
    // Storage refused: nothing to keep (the default stays).
  }
  for (const fn of [...listeners]) fn();
}

function subscribe(fn: () => void): () => void {
  listeners.add(fn);
  const q =
    typeof window !== 'undefined' && typeof window.matchMedia === 'function'
      ? window.matchMedia(COARSE)
      : null;
  q?.addEventListener('change', fn);
  // Another tab of this console changed it.
  const onStorage = (e: StorageEvent) => {
    if (e.key === ESTOP_CONFIRM_KEY || e.key === null) fn();
  };
  if (typeof window !== 'undefined') window.addEventListener('storage', onStorage);
  return () => {
    listeners.delete(fn);
    q?.removeEventListener('change', fn);
    if (typeof window !== 'undefined') window.removeEventListener('storage', onStorage);
  };
}

/** Whether an emergency stop asks first on this console (follows the setting and the screen). */
export function useEstopConfirm(): boolean {
  return useSyncExternalStore(subscribe, estopConfirmNow, () => false);
}
