import { useStore } from 'zustand';
import { useSnapshot } from '../../../fleet/react';
import { Badge, formatNumber, KeyValues, Notice, Panel } from '../../../ui';
import type { TabProps } from '../../../fleet/contract';
import { JobFacts } from '../../../fleet/JobFacts';
import type { PruntSession } from '../session';
import { RateSelect, StartupBanner, useWatchLive } from './common';
import { UpdateLink } from './FilesTab';
import { LiveChart } from './LiveChart';
import './prunt.css';

export function OverviewTab({ session }: TabProps<PruntSession>) {
  useWatchLive(session);
  const snap = useSnapshot(session.ctx, (s) => ({
    activity: s.activity,
    label: s.activityLabel,
    job: s.job,
    positions: s.positions,
    temperatures: s.temperatures,
    link: s.link,
  }));
  const api = useStore(session.store, (s) => s.api);
  const update = useStore(session.store, (s) => s.update);
  const plug = useStore(session.store, (s) => s.smartPlug);
  const tone =
    snap.activity === 'running'
      ? 'ok'
      : snap.activity === 'paused'
        ? 'paused'
        : snap.activity === 'alarm' || snap.activity === 'error'
          ? 'bad'
          : 'muted';
  return (
    <div className="pr-grid" data-testid="prunt-overview">
      <StartupBanner session={session} />
      <Panel title="Machine" actions={<RateSelect session={session} />}>
        <div className="pr-state">
          <Badge tone={tone} testId="prunt-activity">
            {snap.label}
          </Badge>
          {api && (
            <span className="ui-muted">
              {api === 'module' ? 'Prunt module API' : 'Prunt flat API (2025 boards)'}
            </span>
          )}
        </div>
        {/* The server's job record, as every view says it (Prunt reports no progress: unknown). */}
        <JobFacts machine={session.machine.id} job={snap.job} bar={false} />
      </Panel>
      <Panel title="Position">
        <KeyValues items={Object.entries(snap.positions).map(([k, v]) => [k, formatNumber(v, 3, 'mm')])} />
      </Panel>
      <Panel title="Temperatures">
        <KeyValues items={snap.temperatures.map((t) => [t.name, formatNumber(t.current, 1, '°C')])} />
      </Panel>
      {plug?.Enabled && (
        <Panel title="Smart plug">
          <KeyValues
            items={[
              ['Power', plug.Power],
              ['Host', `${plug.Host}${plug.Provider ? ` (${plug.Provider})` : ''}`],
              ['Watchdog', plug.Watchdog_Active ? `active, ${plug.Watchdog_Seconds} s` : 'off'],
              ['Error', plug.Error || 'none'],
            ]}
          />
        </Panel>
      )}
      {update?.result?.Available && (
        <Notice tone="info" title="A software update is available">
          <UpdateLink url={update.result.URL} />
        </Notice>
      )}
      <Panel title="Live chart" className="pr-wide">
        <LiveChart session={session} />
      </Panel>
    </div>
  );
}
