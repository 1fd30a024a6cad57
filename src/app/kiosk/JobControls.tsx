import { useId, useState, type ReactNode } from 'react';
import type { AnyCommand } from '../../fleet/commands';
import type { MachineSession } from '../../fleet/contract';
import { ESTOP_QUESTION, ESTOP_SAID, useEstopConfirm } from '../../fleet/estop-confirm';
import { CommandButton, useRole } from '../../fleet/react';
import { roleAtLeast } from '../../fleet/types';
import { Button } from '../../ui';
import { JOB_CONTROL_ROLE, JOB_CONTROL_WORDS, type JobControlKind, type KioskFamily } from './per-family';

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
    const word = JOB_CONTROL_WORDS[which];
    return (
      <Control which={which} family={family} kiosk={kiosk}>
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
                      ? ESTOP_SAID
                      : `Stop job sent (${r}): the job ends and cannot be resumed.`,
                })
              : setSaid(null)
          }
        >
          {word}
        </CommandButton>
      </Control>
    );
  };
  return (
    <Row
      kiosk={kiosk}
      pause={control(pause, 'pause', 'primary')}
      resume={control(resume, 'resume', 'primary')}
      stop={control(stop, 'stop', 'danger')}
      estop={control(estop, 'estop', 'danger')}
    >
      {said && (
        <p className="job-said" role="status" data-testid="job-said" data-which={said.which}>
          {said.text}
        </p>
      )}
    </Row>
  );
}

/** Until the machine's family code is loaded (the kiosk's first paint): why nothing can be sent yet. */
export const CONNECTING_WORDS = 'Connecting…';

/**
 * The job control row before the machine's family code has loaded: the same controls in the same
 * places, stop included, from the first paint — disabled, each saying "Connecting…" — so that the
 * row does not appear out of nothing a second or three later (and nothing shifts under a finger).
 * A tap sends nothing; nothing here takes the focus. Replaced by `JobControls` once the session
 * exists (whose buttons say "Connecting…" until the machine answers: fleet/commands.ts).
 */
export function PendingJobControls({ family, kiosk = false }: { family: KioskFamily; kiosk?: boolean }) {
  const role = useRole();
  if (!roleAtLeast(role, JOB_CONTROL_ROLE)) return null;
  const control = (which: JobControlKind, variant: 'primary' | 'danger') => (
    <Control which={which} family={family} kiosk={kiosk}>
      <PendingButton which={which} variant={variant} />
    </Control>
  );
  return (
    <Row
      kiosk={kiosk}
      pending
      pause={control('pause', 'primary')}
      resume={control('resume', 'primary')}
      stop={control('stop', 'danger')}
      estop={family.estop ? control('estop', 'danger') : null}
    />
  );
}

/** A control of the row not usable yet: faint, its reason as text under it (as CommandButton's). */
function PendingButton({ which, variant }: { which: JobControlKind; variant: 'primary' | 'danger' }) {
  const reasonId = useId();
  const stop = which === 'stop' || which === 'estop' || undefined;
  return (
    <span className="ui-cmd unavailable">
      <Button
        variant={variant}
        aria-disabled
        aria-describedby={reasonId}
        title={CONNECTING_WORDS}
        data-testid={`job-pending-${which}`}
        data-stop={stop}
      >
        {JOB_CONTROL_WORDS[which]}
      </Button>
      <span className="ui-cmd-reason small" id={reasonId}>
        {CONNECTING_WORDS}
      </span>
    </span>
  );
}

/** One control's place in the row, with the firmware's own term under it. */
function Control({
  which,
  family,
  kiosk,
  children,
}: {
  which: JobControlKind;
  family: KioskFamily;
  kiosk: boolean;
  children: ReactNode;
}) {
  const term = family.terms[which];
  const word = JOB_CONTROL_WORDS[which];
  return (
    <div
      className={kiosk ? `kiosk-control kiosk-${which}` : `job-control job-${which}`}
      data-kiosk={kiosk ? which : undefined}
      data-job={which}
    >
      {children}
      {term && term !== word && (
        <span className="job-term small ui-muted" data-testid={`job-term-${which}`}>
          {term}
        </span>
      )}
    </div>
  );
}

/** The row: pause and resume on one side, stop job and emergency stop on the other. */
function Row(props: {
  kiosk: boolean;
  pending?: boolean;
  pause: ReactNode;
  resume: ReactNode;
  stop: ReactNode;
  estop: ReactNode;
  children?: ReactNode;
}) {
  const { kiosk } = props;
  return (
    <section
      className={kiosk ? 'kiosk-controls' : 'job-controls'}
      aria-label="Job controls"
      aria-busy={props.pending || undefined}
      data-testid="job-controls"
      data-pending={props.pending || undefined}
    >
      <div className={kiosk ? 'kiosk-job-controls' : 'job-controls-run'}>
        {props.pause}
        {props.resume}
      </div>
      <div className={kiosk ? 'kiosk-stop-controls' : 'job-controls-stop'}>
        {props.stop}
        {props.estop}
      </div>
      {props.children}
    </section>
  );
}
