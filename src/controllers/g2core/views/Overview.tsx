import { useSnapshot, useStoreSelect } from '../../../fleet/react';
import { KeyValues, Panel } from '../../../ui';
import type { G2coreSession } from '../session';
import { Alarms, Controls, Dro, JobProgress, ModalState, StatBadge } from './common';
import { Overrides } from './Overrides';

/** The machine page's first tab: state, alarms, controls, job, DRO, modal state, overrides, version. */
export function OverviewTab({ session }: { session: G2coreSession }) {
  const label = useSnapshot(session.ctx, (s) => s.activityLabel);
  return (
    <div
      className="ui-grid"
      style={{ gridTemplateColumns: 'repeat(auto-fit, minmax(min(100%, 420px), 1fr))' }}
    >
      <Panel title="Machine state" testId="g2-state-panel">
        <div className="g2-state" style={{ marginBottom: 12 }}>
          <StatBadge session={session} />
          <span className="ui-muted">{label}</span>
        </div>
        <Alarms session={session} />
        <Controls session={session} />
        <div style={{ marginTop: 12 }}>
          <JobProgress session={session} />
        </div>
      </Panel>
      <Panel title="Position">
        <Dro session={session} />
      </Panel>
      <Panel title="Modal state">
        <ModalState session={session} />
      </Panel>
      <Overrides session={session} />
      <VersionPanel session={session} />
    </div>
  );
}

function VersionPanel({ session }: { session: G2coreSession }) {
  const v = useStoreSelect(session.detail, (d) => d.version);
  const simulated = session.machine.simulated;
  return (
    <Panel title="Version and build" testId="g2-version">
      {v ? (
        <KeyValues
          items={[
            ['Firmware build', v.fb ?? '—'],
            ['Build string', v.fbs || '—'],
            ['Settings file', v.fbc ?? '—'],
            ['Firmware version', v.fv ?? '—'],
            ['Hardware platform', v.hp ?? '—'],
            ['Hardware version', v.hv ?? '—'],
            ['Board id', v.id ?? '—'],
            ['Message', v.msg ?? '—'],
          ]}
        />
      ) : (
        <span className="ui-muted">Not read yet.</span>
      )}
      {simulated && <p className="ui-muted">Simulated controller: these values come from the simulator.</p>}
    </Panel>
  );
}
