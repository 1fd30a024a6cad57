import {
  createContext,
  useContext,
  useEffect,
  useId,
  useLayoutEffect,
  useRef,
  useState,
  useSyncExternalStore,
  type InputHTMLAttributes,
} from 'react';
import { createTouchLock, type TouchLock } from './touch-lock';

/**
 * Sliders and numeric inputs that lock against touch (as Mainsail's do): while locked they ignore
 * touch and typing, so a glove brushing the screen changes nothing; a deliberate tap on the lock
 * unlocks one, and it locks again by itself after a while unused (touch-lock.ts).
 *
 * Where: `auto` (default) locks on touch screens (`pointer: coarse`); `always` everywhere (the
 * kiosk page); `never` nowhere. Set with `<TouchLockPolicy value="always">`.
 */
export type TouchLockMode = 'auto' | 'always' | 'never';
export const TouchLockPolicy = createContext<TouchLockMode>('auto');

const COARSE = '(pointer: coarse)';

function subscribeCoarse(fn: () => void): () => void {
  if (typeof window === 'undefined' || typeof window.matchMedia !== 'function') return () => undefined;
  const q = window.matchMedia(COARSE);
  q.addEventListener('change', fn);
  return () => q.removeEventListener('change', fn);
}

function coarseNow(): boolean {
  return typeof window !== 'undefined' && typeof window.matchMedia === 'function'
    ? window.matchMedia(COARSE).matches
    : false;
}

export interface TouchLockView {
  /** This control locks here (touch screen or kiosk). */
  lockable: boolean;
  /** Locked now (never when not lockable). */
  locked: boolean;
  toggle(): void;
  /** The control was used: the relock countdown starts again. */
  touch(): void;
}

/** One control's lock, following the policy in force. */
export function useTouchLock(relockAfterMs?: number | null): TouchLockView {
  const mode = useContext(TouchLockPolicy);
  const coarse = useSyncExternalStore(subscribeCoarse, coarseNow, () => false);
  const lockable = mode === 'always' || (mode === 'auto' && coarse);
  const [lock] = useState<TouchLock>(() => createTouchLock(relockAfterMs));
  useEffect(() => () => lock.dispose(), [lock]);
  const locked = useSyncExternalStore(
    lock.subscribe,
    () => lock.locked,
    () => true,
  );
  return {
    lockable,
    locked: lockable && locked,
    toggle: () => (lock.locked ? lock.unlock() : lock.lock()),
    touch: () => lock.touch(),
  };
}

function LockIcon({ open }: { open: boolean }) {
  return (
    <svg viewBox="0 0 24 24" width="28" height="28" aria-hidden="true" focusable="false">
      <rect x="4.5" y="10.5" width="15" height="10" rx="2" fill="currentColor" />
      <path
        d={open ? 'M8 10.5V7a4 4 0 0 1 7.6-1.7' : 'M8 10.5V7a4 4 0 0 1 8 0v3.5'}
        fill="none"
        stroke="currentColor"
        strokeWidth="2.2"
        strokeLinecap="round"
      />
    </svg>
  );
}

/** The lock's own button: a deliberate tap toggles it. */
export function LockToggle(props: { lock: TouchLockView; label: string; testId?: string }) {
  const { lock, label } = props;
  return (
    <button
      type="button"
      className={`ui-lock-toggle${lock.locked ? ' locked' : ''}`}
      aria-label={lock.locked ? `Unlock ${label}` : `Lock ${label}`}
      title={lock.locked ? `Locked against touch: tap to unlock ${label}` : `Lock ${label}`}
      onClick={lock.toggle}
      data-testid={props.testId}
      data-locked={lock.locked}
    >
      <LockIcon open={!lock.locked} />
    </button>
  );
}

/** A sent value stays shown this long at most while the controller's value has not changed. */
const SENT_SHOWN_MS = 5000;

/**
 * A slider whose value is sent once, when a drag or a key press ends (the native `change` event),
 * not at every step of a drag. `value` null: not known yet (the slider waits). What was dragged
 * to stays shown until `value` changes (the controller's answer) or a few seconds pass; at once
 * the old value again when `onCommit` resolves `false` or throws (not set).
 */
export function LockableSlider(props: {
  label: string;
  value: number | null;
  min: number;
  max: number;
  step: number;
  format?: (v: number) => string;
  onCommit: (value: number) => Promise<boolean | void> | boolean | void;
  /** Why it cannot be used now (disabled, the reason shown), or null. */
  disabledReason?: string | null;
  testId?: string;
  relockAfterMs?: number | null;
}) {
  const id = useId();
  const hintId = useId();
  const lock = useTouchLock(props.relockAfterMs);
  /** The value dragged to, and the value it was dragged from (shown while that is still `value`). */
  const [drag, setDraft] = useState<{ to: number; from: number | null } | null>(null);
  const draft = drag && drag.from === props.value ? drag.to : null;
  const shownTimer = useRef<ReturnType<typeof setTimeout> | null>(null);
  useEffect(
    () => () => {
      if (shownTimer.current) clearTimeout(shownTimer.current);
    },
    [],
  );
  const [busy, setBusy] = useState(false);
  const ref = useRef<HTMLInputElement>(null);
  /** A value is being sent: a second `change` before it settles is not sent again. */
  const sending = useRef(false);
  const shown = draft ?? props.value ?? props.min;
  const latest = useRef({
    value: props.value,
    onCommit: props.onCommit,
    locked: lock.locked,
    touch: lock.touch,
  });
  useLayoutEffect(() => {
    latest.current = { value: props.value, onCommit: props.onCommit, locked: lock.locked, touch: lock.touch };
  });

  useEffect(() => {
    const el = ref.current;
    if (!el) return;
    const onChange = () => {
      const now = latest.current;
      const v = Number(el.value);
      if (sending.current) return;
      if (now.locked || !Number.isFinite(v) || v === now.value) {
        setDraft(null);
        return;
      }
      now.touch();
      sending.current = true;
      setBusy(true);
      void Promise.resolve()
        .then(() => now.onCommit(v))
        .then(
          (r) => r !== false,
          () => false,
        )
        .then((set) => {
          sending.current = false;
          setBusy(false);
          if (shownTimer.current) clearTimeout(shownTimer.current);
          shownTimer.current = null;
          if (!set) setDraft(null);
          else shownTimer.current = setTimeout(() => setDraft(null), SENT_SHOWN_MS);
        });
    };
    el.addEventListener('change', onChange);
    return () => el.removeEventListener('change', onChange);
  }, []);

  const reason = props.disabledReason ?? (props.value === null ? 'Not known yet' : null);
  const format = props.format ?? String;
  return (
    <div
      className={`ui-lockable${lock.locked ? ' locked' : ''}`}
      data-testid={props.testId}
      data-locked={lock.locked}
    >
      <div className="ui-lockable-head">
        <label htmlFor={id}>{props.label}</label>
        <output htmlFor={id} data-testid={props.testId ? `${props.testId}-value` : undefined}>
          {props.value === null && draft === null ? '—' : format(shown)}
        </output>
      </div>
      <div className="ui-lockable-row">
        <input
          ref={ref}
          id={id}
          type="range"
          className="ui-slider"
          min={props.min}
          max={props.max}
          step={props.step}
          value={shown}
          // Locked: the browser gives it no touch, no drag, no keys.
          disabled={lock.locked || busy || reason !== null}
          aria-describedby={hintId}
          aria-valuetext={format(shown)}
          onChange={(e) => {
            if (lock.locked) return;
            lock.touch();
            setDraft({ to: Number(e.target.value), from: props.value });
          }}
        />
        {lock.lockable && (
          <LockToggle
            lock={lock}
            label={props.label}
            testId={props.testId ? `${props.testId}-lock` : undefined}
          />
        )}
      </div>
      <span className="hint ui-muted small" id={hintId}>
        {lock.locked ? 'Locked against touch: tap the lock to use it.' : (reason ?? '')}
      </span>
    </div>
  );
}

/**
 * A text or numeric input that is read-only while locked (no keyboard comes up on a touch screen),
 * with its lock beside it.
 */
export function LockableInput(
  props: InputHTMLAttributes<HTMLInputElement> & {
    /** Names the input on its lock ("Unlock tilt threshold"). */
    lockLabel: string;
    lockTestId?: string;
    relockAfterMs?: number | null;
  },
) {
  const { lockLabel, lockTestId, relockAfterMs, onChange, readOnly, className, ...rest } = props;
  const lock = useTouchLock(relockAfterMs);
  return (
    <span className="ui-lockable-input">
      <input
        {...rest}
        className={`ui-input${className ? ` ${className}` : ''}`}
        readOnly={readOnly || lock.locked}
        data-locked={lock.locked}
        onChange={(e) => {
          if (lock.locked) return;
          lock.touch();
          onChange?.(e);
        }}
      />
      {lock.lockable && <LockToggle lock={lock} label={lockLabel} testId={lockTestId} />}
    </span>
  );
}
