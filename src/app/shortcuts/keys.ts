/**
 * Keyboard shortcuts (pure: the keys, and when they never fire). The component in
 * `Shortcuts.tsx` listens and acts.
 */

export type ShortcutAction = 'help' | 'go-fleet' | 'go-alarms' | 'next' | 'previous' | 'pause-resume';

/** What the help sheet lists, in its order. */
export const SHORTCUTS: ReadonlyArray<{ keys: string[][]; action: ShortcutAction; what: string }> = [
  { keys: [['?']], action: 'help', what: 'Show these shortcuts' },
  { keys: [['g', 'f']], action: 'go-fleet', what: 'Go to the fleet' },
  { keys: [['g', 'a']], action: 'go-alarms', what: 'Go to the alarm centre' },
  { keys: [['j'], [']']], action: 'next', what: 'Next machine (on a machine page, in the fleet’s order)' },
  { keys: [['k'], ['[']], action: 'previous', what: 'Previous machine (on a machine page)' },
  {
    keys: [['p']],
    action: 'pause-resume',
    what: 'Pause or resume the machine on screen (always asks first)',
  },
];

const SINGLE: Readonly<Record<string, ShortcutAction>> = {
  '?': 'help',
  j: 'next',
  ']': 'next',
  k: 'previous',
  '[': 'previous',
  p: 'pause-resume',
};

const AFTER_G: Readonly<Record<string, ShortcutAction>> = { f: 'go-fleet', a: 'go-alarms' };

/** The second key of `g f` must come within this time (ms). */
export const SEQUENCE_MS = 1500;

export interface KeyLike {
  key: string;
  ctrlKey: boolean;
  metaKey: boolean;
  altKey: boolean;
  repeat?: boolean;
  isComposing?: boolean;
  defaultPrevented?: boolean;
  target: EventTarget | null;
}

/** Where typing goes: a shortcut key there is text, never a shortcut. */
export function isTypingTarget(target: EventTarget | null): boolean {
  if (!target || typeof (target as Element).closest !== 'function') return false;
  const el = target as HTMLElement;
  if (el.isContentEditable) return true;
  return el.closest('input, textarea, select, [contenteditable]:not([contenteditable="false"])') !== null;
}

/** A dialog is open (a confirmation, an alarm, the help sheet) or the page is blocked: no shortcut. */
export function pageBusy(doc: Document): boolean {
  return (
    doc.querySelector('dialog[open], [role="dialog"][aria-modal="true"]') !== null ||
    doc.querySelector('[data-testid="app-page"][inert]') !== null
  );
}

/**
 * Reads key presses into actions, keeping the `g` of a two-key sequence. Never with Ctrl, Alt or
 * Meta (the browser's and the system's shortcuts), never while typing, never on a key held down.
 */
export function createKeyReader(now: () => number = Date.now): (e: KeyLike) => ShortcutAction | null {
  let gAt: number | null = null;
  return (e) => {
    const pendingG = gAt !== null && now() - gAt <= SEQUENCE_MS;
    gAt = null;
    if (e.ctrlKey || e.metaKey || e.altKey || e.isComposing || e.defaultPrevented) return null;
    if (isTypingTarget(e.target)) return null;
    if (e.repeat) return null;
    if (pendingG) {
      const second = AFTER_G[e.key];
      if (second) return second;
    }
    if (e.key === 'g') {
      gAt = now();
      return null;
    }
    return SINGLE[e.key] ?? null;
  };
}
