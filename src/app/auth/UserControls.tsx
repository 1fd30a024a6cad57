import { useCallback, useEffect, useState, type FormEvent } from 'react';
import { useStore } from 'zustand';
import { authStore } from '../../fleet/auth';
import { useNow } from '../../fleet/react';
import { Badge, Button, Dialog, Field, Notice } from '../../ui';
import { elevate, endElevation, fetchSession, sessionExtra } from './api';
import './auth.css';

/** The supervisor PIN unlock on an operator's tablet (the top bar's chip, the login page). */

/** Elevation details come from `GET /api/session`: fetch them once if nobody has yet. */
function useSessionExtra(): void {
  const mode = useStore(authStore, (s) => s.mode);
  const loaded = useStore(sessionExtra, (s) => s.loaded);
  useEffect(() => {
    if (mode === 'secured' && !loaded) void fetchSession().catch(() => undefined);
  }, [mode, loaded]);
}

/** A supervisor PIN: 6 to 12 digits (the gateway does not check shorter ones). */
const PIN_DIGITS = /^\d{6,12}$/;

function PinDialog(props: { onDone: () => void }) {
  const [name, setName] = useState('');
  const [pin, setPin] = useState('');
  const [busy, setBusy] = useState(false);
  const [error, setError] = useState<string | null>(null);
  const { onDone } = props;
  const submit = async (e?: FormEvent) => {
    e?.preventDefault();
    if (busy || !name.trim() || !PIN_DIGITS.test(pin)) return;
    setBusy(true);
    setError(null);
    try {
      await elevate(name.trim(), pin);
      onDone();
    } catch (err) {
      setPin('');
      setError(err instanceof Error ? err.message : String(err));
      setBusy(false);
    }
  };
  return (
    <Dialog
      title="Supervisor unlock"
      onCancel={onDone}
      testId="pin-dialog"
      actions={
        <>
          <Button onClick={onDone}>Cancel</Button>
          <Button
            variant="primary"
            busy={busy}
            disabled={busy || !name.trim() || !PIN_DIGITS.test(pin)}
            onClick={() => void submit()}
          >
            Unlock
          </Button>
        </>
      }
    >
      <form onSubmit={(e) => void submit(e)} className="auth-form">
        <p className="ui-muted">
          A supervisor enters their name and PIN to act on this tablet for a few minutes. It then falls back
          to the operator. Everything done meanwhile is logged under the supervisor’s name.
        </p>
        <Field label="Supervisor">
          {(id) => (
            <input
              id={id}
              className="ui-input"
              autoComplete="off"
              autoCapitalize="off"
              value={name}
              onChange={(e) => setName(e.target.value)}
              data-autofocus
            />
          )}
        </Field>
        <Field
          label="PIN"
          hint={pin && pin.length < 6 ? `At least 6 digits (${pin.length} so far).` : '6 to 12 digits.'}
        >
          {(id) => (
            <input
              id={id}
              className="ui-input auth-pin"
              type="password"
              inputMode="numeric"
              autoComplete="off"
              maxLength={12}
              value={pin}
              onChange={(e) => setPin(e.target.value.replace(/\D/g, '').slice(0, 12))}
            />
          )}
        </Field>
        {error && <Notice tone="bad">{error}</Notice>}
        <button type="submit" hidden />
      </form>
    </Dialog>
  );
}

/**
 * For an operator's tablet: "Supervisor unlock" opens the PIN dialog; while unlocked it shows
 * who unlocked it, until when, and "Lock now". Viewers' and supervisors' sessions cannot be
 * unlocked (the gateway refuses).
 */
export function PinUnlock(props: { compact?: boolean }) {
  const mode = useStore(authStore, (s) => s.mode);
  const user = useStore(authStore, (s) => s.user);
  const elevation = useStore(sessionExtra, (s) => s.elevation);
  const [open, setOpen] = useState(false);
  const close = useCallback(() => setOpen(false), []);
  const now = useNow(1000);
  useSessionExtra();
  if (mode !== 'secured' || !user) return null;
  if (elevation) {
    const left = Math.max(0, Math.round((elevation.until - now) / 1000));
    const clock = `${Math.floor(left / 60)}:${String(left % 60).padStart(2, '0')}`;
    // The top bar's chip: who and how long, in the width of a button (the words for a screen reader).
    if (props.compact)
      return (
        <div className="ui-row auth-elevation compact" data-testid="elevation">
          <Badge tone="paused">
            <span className="sr-only">Unlocked by </span>
            {elevation.supervisor} · {clock}
            <span className="sr-only"> left</span>
          </Badge>
          <Button small onClick={() => void endElevation()}>
            Lock
          </Button>
        </div>
      );
    return (
      <div className="ui-row auth-elevation" data-testid="elevation">
        <Badge tone="paused">
          Unlocked by {elevation.supervisor} · {clock} left
        </Badge>
        <Button small={props.compact} onClick={() => void endElevation()}>
          Lock now
        </Button>
      </div>
    );
  }
  if (user.role !== 'operator') return null;
  return (
    <>
      <Button small={props.compact} onClick={() => setOpen(true)} data-testid="pin-unlock">
        Supervisor unlock
      </Button>
      {open && <PinDialog onDone={close} />}
    </>
  );
}
