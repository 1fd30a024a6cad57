import { useSnapshot, useStoreSelect } from '../../../fleet/react';
import type { TabProps } from '../../../fleet/contract';
import { JobFacts } from '../../../fleet/JobFacts';
import { Badge, KeyValues, Notice, Panel, formatNumber, type Tone } from '../../../ui';
import { GRID } from './layout';
import type { XtoolSession } from '../session';
import type { XState } from '../state';
import { frameTerm, frameWords } from '../phrases';

const STATE_TONE: Record<XState, Tone> = {
  unknown: 'muted',
  idle: 'muted',
  'frame-ready': 'info',
  'job-loaded': 'info',
  framing: 'ok',
  running: 'ok',
  button: 'ok',
  paused: 'paused',
  stopping: 'warn',
  alarm: 'bad',
  error: 'bad',
};

/** Status of one laser: big state, progress, job controls, identity. Tablet first. */
export function Overview({ session }: TabProps<XtoolSession>) {
  const ctx = session.ctx;
  const snap = useSnapshot(ctx, (s) => ({ label: s.activityLabel, job: s.job, link: s.link }));
  const d = useStoreSelect(session.detail, (s) => ({
    state: s.machine.state,
    progress: s.progress,
    working: s.working,
    identity: s.identity,
    periphery: s.periphery,
    model: s.model,
    notice: s.notice,
    socketOpen: s.socketOpen,
    source: s.source,
    lastFrame: s.lastFrame,
  }));

  if (d.model.family === 'unsupported') {
    return (
      <Notice tone="bad" title="Unsupported model" testId="xtool-unsupported">
        This device is not an xTool D-series (D1, D1 Pro, D1 Pro 2.0) laser, and other xTool families speak
        another protocol. Nothing is sent to it but a check, now and then, of what it is. It answered:{' '}
        {d.model.answered.join(' · ')}
      </Notice>
    );
  }

  const busy = d.state === 'running' || d.state === 'paused' || d.state === 'framing' || d.state === 'button';
  const waiting = d.state === 'job-loaded' || d.state === 'frame-ready';
  return (
    <div className="ui-grid" style={GRID} data-testid="xtool-overview">
      <Panel title="Laser">
        <div style={{ display: 'grid', gap: 12 }}>
          <div className="ui-row">
            <Badge tone={STATE_TONE[d.state]} testId="xtool-state">
              {d.state === 'button' ? 'busy' : d.state.replace('-', ' ')}
            </Badge>
            <strong style={{ fontSize: 26, lineHeight: 1.2 }} data-testid="xtool-state-label">
              {snap.label}
            </strong>
          </div>
          {waiting && (
            <Notice tone="info" title="Waiting for the button on the machine" testId="xtool-press-button">
              {d.notice ?? 'The file is loaded. Someone at the laser must press its button to start.'}
            </Notice>
          )}
          {busy && snap.job && (
            <>
              {/* The server's job record, as every view says it (fleet/job-facts.ts). */}
              <JobFacts machine={session.machine.id} job={snap.job} />
              <KeyValues testId="xtool-job" items={[['Current line', d.progress?.line ?? '—']]} />
            </>
          )}
          <p className="ui-muted" style={{ margin: 0 }}>
            Jobs start with the button on the machine. State from{' '}
            {d.source === 'socket'
              ? `the live socket${d.lastFrame ? `: ${frameWords(d.lastFrame.raw)}` : ''}`
              : d.source === 'command'
                ? "the laser's answer to the last command"
                : 'the last poll'}
            {d.socketOpen ? '' : ' · live socket not connected, polling only'}.
            {d.source === 'socket' && d.lastFrame && (
              <span className="small" data-testid="xtool-frame-term">
                {' '}
                (xTool: {frameTerm(d.lastFrame.raw)})
              </span>
            )}
          </p>
        </div>
      </Panel>
      <Panel title="Device">
        <KeyValues
          testId="xtool-identity"
          items={[
            ['Model', d.identity.type],
            ['Name', d.identity.name],
            ['Laser module', d.identity.power !== null ? `${formatNumber(d.identity.power, 0)} W` : null],
            ['Firmware', d.identity.version],
            ['Serial', d.identity.sn],
            ['MAC', d.identity.mac],
            [
              'SD card',
              d.periphery?.sdCard === undefined ? (
                'not reported'
              ) : d.periphery.sdCard ? (
                <Badge tone="ok">inserted</Badge>
              ) : (
                <Badge tone="warn">no card</Badge>
              ),
            ],
            ['Status', d.periphery?.status ?? null],
            ['Working code', d.working ? `${d.working.raw} (${d.working.code})` : null],
          ]}
        />
      </Panel>
    </div>
  );
}
