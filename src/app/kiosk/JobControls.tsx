import { useState } from 'react';
import type { AnyCommand } from '../../fleet/commands';
import type { MachineSession } from '../../fleet/contract';
import { ESTOP_QUESTION, ESTOP_SAID, useEstopConfirm } from '../../fleet/estop-confirm';
import { CommandButton, useRole } from '../../fleet/react';
import { roleAtLeast } from '../../fleet/types';
import { JOB_CONTROL_WORDS, type JobControlKind, type KioskFamily } from './per-family';

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
                      ? ESTOP_SAID
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
