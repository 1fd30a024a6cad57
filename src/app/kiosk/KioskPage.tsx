import { Suspense, useEffect, useMemo, type ComponentType } from 'react';
import { familyLabel, useController } from '../../controllers';
import { linkWords, type MachineSession, type TabProps } from '../../fleet/contract';
import { showDetail, type MachineRuntime } from '../../fleet/fleet';
import { useSnapshot } from '../../fleet/react';
import { mostSevereAlarm, type Activity } from '../../fleet/types';
import { Badge, Loading, ProgressBar } from '../../ui';
import { useJobWords } from '../../fleet/job-facts';
import { TouchLockPolicy } from '../../ui/Lockable';
import { MachineAge } from '../Age';
import { ErrorBoundary } from '../ErrorBoundary';
import { MachineProblems } from '../MachineProblems';
import { cardOf, firstScreenShown } from '../first-screen';
import { LINK_TONE, shownState } from '../status';
import { JobControls, PendingJobControls } from './JobControls';
import { KIOSK_FAMILIES } from './per-family';
import { useScreenWakeLock, type WakeStatus } from './wake-lock';

/** A job is under way: the screen stays on. */
const JOB_UNDER_WAY: ReadonlySet<Activity> = new Set<Activity>(['running', 'paused', 'stopping']);

/**
 * The kiosk page (`/m/<id>?kiosk`): one machine on a tablet at the machine, full screen, nothing
 * to navigate away with. Very large state, progress and time left; the job controls the user's
 * role may use, sized for gloves, stop set well apart from pause and resume; sliders and numeric
 * inputs locked against touch; the screen kept on while a job runs.
 */
export function KioskPage({ rt }: { rt: MachineRuntime }) {
  const info = rt.info;
  const mod = useController(info.kind);
  // The session's card, or the console server's reading of the machine until the session's first
  // answer (first-screen.ts): the tablet shows the machine before its family's code is loaded.
  const card = useMemo(() => cardOf(info), [info]);
  const s = useSnapshot(rt, (x) => ({
    ...card(x),
    identity: x.identity,
    retryAt: x.retryAt,
  }));
  // The job in the words of every view: the server's record first (fleet/job-facts.ts).
  const job = useJobWords(info.id, s.job);
  // The machine's details at full pace while the kiosk shows it (as the machine page does).
  useEffect(() => showDetail(info.id), [info.id]);
  // With the server's reading this is the first screen: the family's code may load now (boot.ts).
  useEffect(() => {
    if (info.watch) firstScreenShown();
  }, [info.watch]);
  const wake = useScreenWakeLock(JOB_UNDER_WAY.has(s.activity));
  const session = rt.session;
  const family = KIOSK_FAMILIES[info.kind];
  const LoginForm = mod?.LoginForm as ComponentType<TabProps<MachineSession>> | undefined;
  const Extra = family?.Extra;
  const alarm = mostSevereAlarm(s.alarms.filter((a) => !a.acknowledged));
  const shown = shownState(s.activity, s.alarms);

  return (
    <TouchLockPolicy value="always">
      <div
        className={`kiosk-page activity-${shown.activity}`}
        data-testid={`kiosk-${info.id}`}
        data-activity={shown.activity}
      >
        <header className="kiosk-head">
          <div className="kiosk-title">
            <h1>{info.name}</h1>
            <div className="ui-muted">
              {familyLabel(info.kind)}
              {s.identity ? ` · ${s.identity}` : ''}
            </div>
          </div>
          <div className="kiosk-link">
            <Badge tone={LINK_TONE[s.link]} testId="kiosk-link">
              {linkWords(s.link)}
            </Badge>
            <MachineAge rt={rt} testId="kiosk-data-age" />
          </div>
        </header>
        {info.simulated && (
          <div className="sim-banner" role="note" data-testid="simulated-banner">
            Simulated machine: nothing real moves.
          </div>
        )}
        <MachineProblems rt={rt} LoginForm={LoginForm} />

        <section className="kiosk-state" aria-label="State">
          <div className={`kiosk-activity tone-${shown.tone}`} data-testid="kiosk-activity">
            {shown.words}
          </div>
          <div className="kiosk-label" data-testid="kiosk-label">
            {s.activityLabel}
          </div>
          {alarm && (
            <div
              className={`kiosk-alarm tone-${alarm.severity === 'critical' ? 'bad' : alarm.severity === 'warning' ? 'warn' : 'info'}`}
              role="alert"
              data-testid="kiosk-alarm"
            >
              {alarm.severity !== 'info' && <span aria-hidden="true">⚠ </span>}
              {alarm.message}
            </div>
          )}
        </section>

        <section className="kiosk-job" aria-label="Job">
          {s.job && job ? (
            <>
              <div className="kiosk-job-name" title={job.name} data-testid="kiosk-job-name">
                {job.name}
              </div>
              <ProgressBar value={job.fraction} label="Job progress" />
              <div className="kiosk-figures">
                <div>
                  <span className="kiosk-big" data-testid="kiosk-progress">
                    {job.fraction === null ? '—' : job.percent}
                  </span>
                  <span className="kiosk-unit">{job.fraction === null ? job.percent : 'done'}</span>
                </div>
                <div>
                  <span className="kiosk-big" data-testid="kiosk-remaining">
                    {job.remainingFigure}
                  </span>
                  <span className="kiosk-unit">{job.remainingNote}</span>
                </div>
              </div>
              <div className="kiosk-running ui-muted" data-testid="kiosk-job-running">
                {job.runningFor}
              </div>
            </>
          ) : (
            <div className="kiosk-no-job ui-muted" data-testid="kiosk-no-job">
              {/* Until the machine answers, nobody knows (the server's reading may name no job). */}
              {s.link === 'connecting' ? 'Job: waiting for the machine…' : 'No job'}
            </div>
          )}
        </section>

        {/* The row from the first paint: disabled, "Connecting…", until the family's code is here. */}
        {family &&
          (session ? (
            <JobControls session={session} family={family} kiosk />
          ) : (
            !rt.error && <PendingJobControls family={family} kiosk />
          ))}
        {session && !family && (
          <p className="ui-muted kiosk-note" data-testid="kiosk-no-controls">
            This machine takes no commands from the console: use its own panel.
          </p>
        )}
        {session && Extra && (
          <div className="kiosk-extra">
            <ErrorBoundary label={`${info.name} · controls`}>
              <Suspense fallback={<Loading />}>
                <Extra session={session} />
              </Suspense>
            </ErrorBoundary>
          </div>
        )}
        <WakeNote status={wake} />
      </div>
    </TouchLockPolicy>
  );
}

const WAKE_WORDS: Record<WakeStatus, string | null> = {
  off: null,
  waiting: null,
  held: 'The screen stays on while the job runs.',
  unsupported:
    'This browser cannot keep the screen on (no Screen Wake Lock): set the tablet’s screen timeout instead.',
  insecure:
    'The screen cannot be kept on: the wake lock needs a secure connection (HTTPS, or localhost). Set the tablet’s screen timeout instead.',
  refused: 'The browser refused to keep the screen on (power saving?): asking again in a while.',
};

function WakeNote({ status }: { status: WakeStatus }) {
  const words = WAKE_WORDS[status];
  if (!words) return null;
  return (
    <p className={`kiosk-wake small wake-${status}`} data-testid="kiosk-wake" data-status={status}>
      {words}
    </p>
  );
}
