import { CommandButton, useSnapshot, useStoreSelect } from '../../../fleet/react';
import { KeyValues, Panel } from '../../../ui';
import type { G2coreSession } from '../session';
import { Alarms, Controls, Dro, JobProgress, ModalState, StatBadge } from './common';

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

const STEPS = [-0.1, 0.1] as const;

function Overrides({ session }: { session: G2coreSession }) {
  const { mfo, sso, enabled } = useStoreSelect(session.detail, (d) => ({
    mfo: typeof d.sr.mfo === 'number' ? d.sr.mfo : null,
    sso: typeof d.sr.sso === 'number' ? d.sr.sso : null,
    enabled: d.overrides,
  }));
  if (mfo === null && sso === null) return null;
  const { commands: runner, snapshot } = session.ctx;
  const row = (key: 'mfo' | 'sso', value: number, on: boolean | null, what: string) => (
    <div style={{ marginBottom: 12 }} data-testid={`g2-override-${key}`}>
      <div className="ui-row" style={{ justifyContent: 'space-between' }}>
        <strong>{what}</strong>
        <span style={{ fontSize: '1.4rem' }}>{Math.round(value * 100)} %</span>
      </div>
      {on === false && (
        <div className="ui-muted">
          Disabled in the settings ({key}e = 0): the factor is stored but not applied.
        </div>
      )}
      <div className="g2-choices">
        {STEPS.map((d) => (
          <CommandButton
            key={d}
            runner={runner}
            snapshot={snapshot}
            command={session.setOverride}
            args={{ key, value: Math.round(Math.min(2, Math.max(0.05, value + d)) * 100) / 100 }}
          >
            {d > 0 ? '+10 %' : '−10 %'}
          </CommandButton>
        ))}
        <CommandButton
          runner={runner}
          snapshot={snapshot}
          command={session.setOverride}
          args={{ key, value: 1 }}
        >
          100 %
        </CommandButton>
      </div>
    </div>
  );
  return (
    <Panel title="Overrides">
      {mfo !== null && row('mfo', mfo, enabled.mfoe, 'Feed override')}
      {sso !== null && row('sso', sso, enabled.ssoe, 'Spindle override')}
    </Panel>
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
