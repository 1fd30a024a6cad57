import type { RegisterSWOptions } from 'virtual:pwa-register';

/**
 * Registers the service worker (src/app/pwa/options.ts) with vite-plugin-pwa's `registerSW`
 * (register.ts passes it; main.tsx loads that chunk only when pwaWanted()).
 *
 * Updates: the browser looks for a new sw.js (served no-cache) at each navigation, and a kiosk
 * tablet that never navigates asks every hour. A new version takes over at once (autoUpdate);
 * the page then reloads itself as soon as nobody is using it (reloadWhenIdle), not in the
 * middle of a dialog, a command in flight or a half-typed field.
 */

/** How often an open page asks for a new version. */
export const UPDATE_CHECK_MS = 60 * 60_000;

export function startPwa(registerSW: (options: RegisterSWOptions) => unknown): void {
  registerSW({
    onNeedReload: () => void reloadWhenIdle(),
    onRegisteredSW: (_url, r) => {
      if (!r) return;
      setInterval(() => {
        if (navigator.onLine && !r.installing) r.update().catch(() => undefined);
      }, UPDATE_CHECK_MS);
    },
    onRegisterError: (e: unknown) => console.warn('Shopdeck: the service worker was not registered', e),
  });
}

/** No input for this long counts as nobody using the page. */
export const IDLE_MS = 30_000;
const CHECK_MS = 5_000;

/**
 * Someone is in the middle of something: a dialog is open, a command is in flight (aria-busy),
 * or the focused text field holds something typed.
 */
export function pageBusy(doc: Document = document): boolean {
  if (doc.querySelector('dialog[open], [role="dialog"], [role="alertdialog"], [aria-busy="true"]'))
    return true;
  const a = doc.activeElement;
  if (!a) return false;
  if (a instanceof HTMLElement && a.isContentEditable) return true;
  return (a instanceof HTMLInputElement || a instanceof HTMLTextAreaElement) && a.value !== '';
}

/**
 * Calls `reload` once the page is not busy and either hidden or without input for IDLE_MS.
 * Returns a function that cancels it.
 */
export function reloadWhenIdle(
  reload: () => void = () => location.reload(),
  doc: Document = document,
  idleMs = IDLE_MS,
): () => void {
  let lastInput = Date.now();
  const onInput = (): void => {
    lastInput = Date.now();
  };
  const inputs = ['pointerdown', 'keydown', 'wheel'] as const;
  const check = (): void => {
    if (pageBusy(doc)) return;
    if (doc.visibilityState !== 'hidden' && Date.now() - lastInput < idleMs) return;
    stop();
    reload();
  };
  const timer = setInterval(check, CHECK_MS);
  for (const e of inputs) doc.addEventListener(e, onInput, { capture: true, passive: true });
  doc.addEventListener('visibilitychange', check);
  function stop(): void {
    clearInterval(timer);
    for (const e of inputs) doc.removeEventListener(e, onInput, { capture: true });
    doc.removeEventListener('visibilitychange', check);
  }
  return stop;
}
