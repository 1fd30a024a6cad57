import { useState, useSyncExternalStore } from 'react';
import type { AnyCommand } from '../../fleet/commands';
import type { MachineSession } from '../../fleet/contract';
import { CommandButton, useRole } from '../../fleet/react';
import { roleAtLeast } from '../../fleet/types';
import { JOB_CONTROL_WORDS, type JobControlKind, type KioskFamily } from './per-family';

/** A touch screen (also one beside a mouse: a tablet with a keyboard case). */
const COARSE = '(pointer: coarse), (any-pointer: coarse)';
/** This console's choice (localStorage): `on` or `off`; unset follows the screen (on for touch). */
export const ESTOP_CONFIRM_KEY = 'shopdeck.estop-confirm';

function subscribeCoarse(fn: () => void): () => void {
  if (typeof window === 'undefined' || typeof window.matchMedia !== 'function') return () => undefined;
  const q = window.matchMedia(COARSE);
  q.addEventListener('change', fn);
  return () => q.removeEventListener('change', fn);
}

function estopConfirmNow(): boolean {
  if (typeof window === 'undefined') return false;
  let set: string | null = null;
  try {
    set = window.localStorage.getItem(ESTOP_CONFIRM_KEY);
  } catch {
    // Storage refused (private mode): the default below.
  }
  if (set === 'on') return true;
  if (set === 'off') return false;
  return typeof window.matchMedia === 'function' && window.matchMedia(COARSE).matches;
}

/**
 * Whether an emergency stop asks first on this console: a setting per console (`ESTOP_CONFIRM_KEY`),
 * on by default on touch screens, where a brush of a glove is a tap.
 */
export function useEstopConfirm(): boolean {
  return useSyncExternalStore(subscribeCoarse, estopConfirmNow, () => false);
}

const ESTOP_QUESTION =
  'Emergency stop: halt the machine now? Motion and heaters stop at once and the job ends; it cannot be resumed.';

/** What the dismiss of each control's question keeps. */
const KEEP: Record<Exclude<JobControlKind, 'stop'>, string> = {
  pause: 'Keep running',
  resume: 'Stay paused',
  estop: 'Keep running',
};

/**
 * The job control row, the same on the kiosk and on every family's machine page: pause and resume
 * on one side, stop job (and the emergency stop where there is one) on the other, a control's
 * width or more apart; one vocabulary ("Stop job") with the firmware's own term under it
 * ("Kill (^D)"). Each is the family's declared command (roles, availability, confirmation, audit,
 * sent once: a button is disabled while its command is in flight). After a stop, what it did is
 * said on screen.
 */
export function JobControls({
  session,
  family,
  kiosk = false,
}: {
  session: MachineSession;
  family: KioskFamily;
  kiosk?: boolean;
}) {
  const role = useRole();
  const estopConfirm = useEstopConfirm();
  const [said, setSaid] = useState<{ which: JobControlKind; text: string } | null>(null);
  const { commands: runner, snapshot } = session.ctx;
  const pick = (id: string | undefined): AnyCommand | null => (id ? (session.commands[id] ?? null) : null);
  const pause = pick(family.pause);
  const resume = pick(family.resume);
  const stop = pick(family.stop);
  const estop = pick(family.estop);
  const usable = [pause, resume, stop, estop].filter(
    (c): c is AnyCommand => c !== null && roleAtLeast(role, c.role),
  );
  if (usable.length === 0)
    return (
      <p className="ui-muted kiosk-note" data-testid="kiosk-no-controls">
        Your role ({role}) has no controls on this machine.
      </p>
    );
  const control = (
    cmd: AnyCommand | null,
    which: JobControlKind,
    variant: 'secondary' | 'primary' | 'danger',
  ) => {
    if (!cmd || !roleAtLeast(role, cmd.role)) return null;
    const term = family.terms[which];
    const word = JOB_CONTROL_WORDS[which];
    return (
      <div
        className={kiosk ? `kiosk-control kiosk-${which}` : `job-control job-${which}`}
        data-kiosk={kiosk ? which : undefined}
        data-job={which}
      >
        <CommandButton
          runner={runner}
          snapshot={snapshot}
          command={cmd}
          args={undefined as never}
          variant={variant}
          label={word}
          dismissLabel={which === 'stop' ? family.keep : KEEP[which]}
          confirmText={which === 'estop' && estopConfirm ? ESTOP_QUESTION : undefined}
          onDone={(r: string) =>
            which === 'estop' || which === 'stop'
              ? setSaid({
                  which,
                  text:
                    which === 'estop'
                      ? 'Emergency stop sent: the machine is halted and the job has ended. Check the machine before the next job.'
                      : `Stop job sent (${r}): the job ends and cannot be resumed.`,
                })
              : setSaid(null)
          }
        >
          {word}
        </CommandButton>
        {term && term !== word && (
          <span className="job-term small ui-muted" data-testid={`job-term-${which}`}>
            {term}
          </span>
        )}
      </div>
    );
  };
  return (
    <section
      className={kiosk ? 'kiosk-controls' : 'job-controls'}
      aria-label="Job controls"
      data-testid="job-controls"
    >
      <div className={kiosk ? 'kiosk-job-controls' : 'job-controls-run'}>
        {control(pause, 'pause', 'primary')}
        {control(resume, 'resume', 'primary')}
      </div>
      <div className={kiosk ? 'kiosk-stop-controls' : 'job-controls-stop'}>
        {control(stop, 'stop', 'danger')}
        {control(estop, 'estop', 'danger')}
      </div>
      {said && (
        <p className="job-said" role="status" data-testid="job-said" data-which={said.which}>
          {said.text}
        </p>
      )}
    </section>
  );
}
