import { useState } from 'react';
import { useEstopConfirm } from '../../../fleet/estop-confirm';
import { CommandButton, useStoreSelect } from '../../../fleet/react';
import { Button, Panel } from '../../../ui';
import type { AxisLetter, G2coreSession } from '../session';
import { Alarms, Dro, StatBadge, WhyNot } from './common';

const STEPS_MM = [0.1, 1, 10, 50];
const STEPS_IN = [0.001, 0.01, 0.1, 1];
const FEEDS_MM = [100, 500, 1000, 3000];
const FEEDS_IN = [5, 20, 50, 100];

const STOP_QUESTION =
  'STOP: halt what moves now? The jog or homing stops, else the running job ends (a stopped job cannot be resumed).';
const STOP_SAID =
  'STOP sent (kill): the motion has stopped; a job that was running has ended and cannot be resumed.';

/** Jog (relative moves at a chosen step and feed), homing, and a big stop. */
export function JogTab({ session }: { session: G2coreSession }) {
  const { axes, inches } = useStoreSelect(session.detail, (d) => ({ axes: d.axes, inches: d.sr.unit === 0 }));
  const steps = inches ? STEPS_IN : STEPS_MM;
  const feeds = inches ? FEEDS_IN : FEEDS_MM;
  const [stepIdx, setStepIdx] = useState(1);
  const [feedIdx, setFeedIdx] = useState(2);
  const step = steps[stepIdx] ?? steps[0]!;
  const feed = feeds[feedIdx] ?? feeds[0]!;
  const unit = inches ? 'in' : 'mm';
  const { commands: runner, snapshot } = session.ctx;
  // The emergency stop's setting (on by default on touch screens): the big STOP asks first.
  const stopConfirm = useEstopConfirm();
  const [stopSaid, setStopSaid] = useState(false);
  return (
    <div
      className="ui-grid"
      style={{ gridTemplateColumns: 'repeat(auto-fit, minmax(min(100%, 420px), 1fr))' }}
    >
      <Panel title="Position" actions={<StatBadge session={session} />}>
        <Alarms session={session} />
        <Dro session={session} compact />
        <div style={{ marginTop: 16, display: 'flex', justifyContent: 'center' }}>
          <CommandButton
            runner={runner}
            snapshot={snapshot}
            command={session.stopJog}
            args={undefined}
            variant="danger"
            testId="g2-bigstop"
            label="STOP"
            confirmText={stopConfirm ? STOP_QUESTION : undefined}
            dismissLabel="Keep moving"
            onDone={() => setStopSaid(true)}
          >
            <span className="g2-bigstop">STOP</span>
          </CommandButton>
        </div>
        {stopSaid && (
          <p className="job-said" role="status" data-testid="g2-stop-said">
            {STOP_SAID}
          </p>
        )}
        <p className="ui-muted" style={{ textAlign: 'center' }}>
          Stops whatever moves: the jog or homing, else the running job (a stopped job cannot be resumed).
        </p>
      </Panel>
      <Panel title="Jog" testId="g2-jog">
        <div className="ui-muted" style={{ marginBottom: 6 }}>
          Step ({unit})
        </div>
        <div className="g2-choices" role="group" aria-label="Jog step">
          {steps.map((s, i) => (
            <Button
              key={s}
              aria-pressed={i === stepIdx}
              onClick={() => setStepIdx(i)}
              data-testid={`g2-step-${s}`}
            >
              {s}
            </Button>
          ))}
        </div>
        <div className="ui-muted" style={{ margin: '10px 0 6px' }}>
          Feed ({unit}/min)
        </div>
        <div className="g2-choices" role="group" aria-label="Jog feed">
          {feeds.map((f, i) => (
            <Button key={f} aria-pressed={i === feedIdx} onClick={() => setFeedIdx(i)}>
              {f}
            </Button>
          ))}
        </div>
        <WhyNot session={session} command={session.jog} />
        <div className="g2-jog" style={{ marginTop: 12 }}>
          {axes.map((a: AxisLetter) => (
            <div className="row" key={a}>
              <span className="label">{a.toUpperCase()}</span>
              <CommandButton
                runner={runner}
                snapshot={snapshot}
                command={session.jog}
                args={{ axis: a, distance: -step, feed }}
                testId={`g2-jog-${a}-minus`}
              >
                {`${a.toUpperCase()}−`}
              </CommandButton>
              <CommandButton
                runner={runner}
                snapshot={snapshot}
                command={session.jog}
                args={{ axis: a, distance: step, feed }}
                testId={`g2-jog-${a}-plus`}
              >
                {`${a.toUpperCase()}+`}
              </CommandButton>
            </div>
          ))}
        </div>
      </Panel>
      <Panel title="Home (G28.2)">
        <p className="ui-muted">Homing moves each axis to its switch; the machine must be idle.</p>
        <WhyNot session={session} command={session.home} />
        <div className="g2-choices">
          <CommandButton
            runner={runner}
            snapshot={snapshot}
            command={session.home}
            args={{ axes }}
            testId="g2-home-all"
          >
            Home all
          </CommandButton>
          {axes.map((a) => (
            <CommandButton
              key={a}
              runner={runner}
              snapshot={snapshot}
              command={session.home}
              args={{ axes: [a] }}
              testId={`g2-home-${a}`}
            >
              {`Home ${a.toUpperCase()}`}
            </CommandButton>
          ))}
        </div>
      </Panel>
    </div>
  );
}
