import { confirmationText, type AnyCommand, type CommandRunner } from '../../fleet/commands';

/**
 * The `p` shortcut: the family's own pause or resume command (the one its buttons send), sent
 * through the machine's command runner, and only after a confirmation — even a pause that its
 * button sends at once, because a key press is easier to make by mistake than a tap.
 */

/** A family's pause and resume, by the ids they declare (`<kind>.pause`, g2core's `feedhold`). */
const PAUSE_ID = /^[a-z0-9]+\.(pause|feedhold)$/;
const RESUME_ID = /^[a-z0-9]+\.resume$/;

export type PauseChoice =
  { kind: 'send'; command: AnyCommand; question: string } | { kind: 'none'; reason: string };

/** What `p` offers on this machine now: pause when it can pause, resume when it can resume. */
export function choosePauseResume(
  commands: Readonly<Record<string, AnyCommand>>,
  runner: Pick<CommandRunner, 'blockedReason'>,
  machineName: string,
): PauseChoice {
  const all = Object.values(commands);
  const pause = all.find((c) => PAUSE_ID.test(c.id));
  const resume = all.find((c) => RESUME_ID.test(c.id));
  if (!pause && !resume) return { kind: 'none', reason: `${machineName} cannot be paused from the console.` };
  const pauseBlocked = pause ? runner.blockedReason(pause) : null;
  if (pause && pauseBlocked === null)
    return { kind: 'send', command: pause, question: questionOf(pause, machineName) };
  const resumeBlocked = resume ? runner.blockedReason(resume) : null;
  if (resume && resumeBlocked === null)
    return { kind: 'send', command: resume, question: questionOf(resume, machineName) };
  return {
    kind: 'none',
    reason: `Nothing to pause or resume: ${pauseBlocked ?? resumeBlocked ?? 'not available'}`,
  };
}

/** The family's confirmation text, else one of ours ("Pause Laser 1?"). */
function questionOf(cmd: AnyCommand, machineName: string): string {
  return confirmationText(cmd, undefined as never) ?? `${cmd.label} ${machineName}?`;
}
