import { memo, Suspense, useEffect, useId, useMemo } from 'react';
import { useStore } from 'zustand';
import { familyLabel, useController } from '../controllers';
import { getRuntime, fleetStore, type MachineRuntime } from '../fleet/fleet';
import { lazyView, preloadViews } from '../fleet/lazy';
import { linkWords } from '../fleet/contract';
import { useDerived, useSnapshot } from '../fleet/react';
import { useJobWords } from '../fleet/job-facts';
import { mostSevereAlarm, type MachineInfo } from '../fleet/types';
import { Badge, Button, EmptyState, Loading, Notice, ProgressBar } from '../ui';
import { MachineAge } from './Age';
import { ErrorBoundary } from './ErrorBoundary';
import type { FleetGroup } from './fleet-views/arrange';
import { FleetToolbar } from './fleet-views/FleetToolbar';
import { useArrangement } from './fleet-views/live';
import { useFleetPrefs } from './fleet-views/usePrefs';
import { MachinePage } from './pages';
import { Link, usePageTitle } from './router';
import { cardOf, firstScreenShown } from './first-screen';
import { LINK_TONE, shownState, summaryCounts, type SummaryBucket } from './status';
import { useRuntimesOf } from './runtimes';

/** The dense list view: its own chunk (the tiles are the first screen). */
const FleetList = lazyView(() => import('./fleet-views/FleetList'), 'FleetList');

export function FleetPage() {
  const { machines, status, error } = useStore(fleetStore);
  usePageTitle('Fleet');
  return (
    <>
      {/* The page's heading, for a screen reader's outline (the top bar shows where one is). */}
      <h1 className="sr-only">Fleet</h1>
      {status === 'loading' ? (
        <EmptyState>Loading the fleet…</EmptyState>
      ) : status === 'error' ? (
        <Notice tone="bad" title="The fleet could not be loaded">
          {error}
        </Notice>
      ) : machines.length === 0 ? (
        <EmptyState>
          No machines. Add them to <code>machines.json</code> (see the README), or sign in to see yours.
        </EmptyState>
      ) : (
        <FleetBody machines={machines} />
      )}
    </>
  );
}

function FleetBody({ machines }: { machines: MachineInfo[] }) {
  const [prefs, update] = useFleetPrefs();
  const groups = useArrangement(machines, prefs);
  const byId = useMemo(() => new Map(machines.map((m) => [m.id, m])), [machines]);
  const shown = groups.reduce((n, g) => n + g.ids.length, 0);
  // The first screen is up: the families' code may load now (boot.ts).
  useEffect(() => firstScreenShown(), []);
  return (
    <div className="fleet" data-view={prefs.view}>
      <SummaryBar machines={machines} />
      <FleetToolbar prefs={prefs} update={update} machines={machines} shown={shown} />
      {shown === 0 ? (
        <EmptyState>
          No machine matches this filter.{' '}
          <Button onClick={() => update({ state: 'all', family: 'all', q: '' })}>Show all machines</Button>
        </EmptyState>
      ) : prefs.view === 'list' ? (
        <Suspense fallback={<Loading />}>
          <FleetList groups={groups} byId={byId} />
        </Suspense>
      ) : (
        <div data-testid="fleet-tiles" className={groups[0]?.label === null ? undefined : 'fleet-groups'}>
          {groups.map((g) =>
            g.label === null ? (
              <section key={g.key} aria-label="Machines">
                {/* The tiles' names are h3: one level under the page's h1, as in a group. */}
                <h2 className="sr-only">Machines</h2>
                <Tiles ids={g.ids} byId={byId} />
              </section>
            ) : (
              <TileGroup key={g.key} group={g} byId={byId} />
            ),
          )}
        </div>
      )}
    </div>
  );
}

function TileGroup({ group, byId }: { group: FleetGroup; byId: ReadonlyMap<string, MachineInfo> }) {
  const id = useId();
  return (
    <section
      className="fleet-group"
      aria-labelledby={id}
      data-testid={`fleet-group-${group.key}`}
      // Its width asks for its tiles' (fleet-views.css): small groups share a row.
      style={{ '--tiles': group.ids.length } as React.CSSProperties}
    >
      <h2 id={id}>
        {group.label} <span className="ui-muted">({group.ids.length})</span>
      </h2>
      <Tiles ids={group.ids} byId={byId} />
    </section>
  );
}

function Tiles({ ids, byId }: { ids: readonly string[]; byId: ReadonlyMap<string, MachineInfo> }) {
  return (
    <div className="tiles">
      {ids.map((id) => {
        const m = byId.get(id);
        return (
          m && (
            <ErrorBoundary key={m.id} label={m.name} compact>
              <MachineTile info={m} />
            </ErrorBoundary>
          )
        );
      })}
    </div>
  );
}

const SUMMARY: Array<{
  key: SummaryBucket;
  label: string;
  tone: 'ok' | 'info' | 'paused' | 'bad' | 'muted';
}> = [
  { key: 'running', label: 'running', tone: 'ok' },
  { key: 'idle', label: 'idle', tone: 'info' },
  { key: 'paused', label: 'paused', tone: 'paused' },
  { key: 'alarm', label: 'in alarm', tone: 'bad' },
  { key: 'offline', label: 'offline', tone: 'muted' },
  { key: 'unknown', label: 'state unknown', tone: 'muted' },
];

/**
 * Counts by displayed state (status.ts): each machine in exactly one, so they add up to the
 * fleet. Subscribes to each machine's snapshot for two fields only.
 */
function SummaryBar({ machines }: { machines: MachineInfo[] }) {
  const { rts, sources } = useRuntimesOf(machines);
  const counts = useDerived(
    sources,
    () =>
      summaryCounts(
        rts.map((rt) => {
          // What the tile shows: the session's card, or the server's reading until it answers.
          const c = cardOf(rt.info)(rt.snapshot.getState());
          return shownState(c.activity, c.alarms);
        }),
      ),
    (a, b) => SUMMARY.every((d) => a[d.key] === b[d.key]),
  );
  return (
    <div className="summary" data-testid="fleet-summary" aria-label="Fleet summary">
      <span className="summary-total">{machines.length} machines</span>
      {SUMMARY.map(
        (d) =>
          // "state unknown" only when some machine is (the others always, zero included).
          (d.key !== 'unknown' || counts.unknown > 0) && (
            <Badge key={d.key} tone={counts[d.key] > 0 ? d.tone : 'muted'} testId={`summary-${d.key}`}>
              {counts[d.key]} {d.label}
            </Badge>
          ),
      )}
    </div>
  );
}

/** Memo: a new order or grouping of the page does not re-render a tile (its machine's data does). */
export const MachineTile = memo(function MachineTile({ info }: { info: MachineInfo }) {
  const rt = getRuntime(info.id);
  if (!rt) return null;
  return <TileBody info={info} rt={rt} />;
});

function TileBody({ info, rt }: { info: MachineInfo; rt: MachineRuntime }) {
  // The session's card, or the console server's reading until the session's first answer.
  const s = useSnapshot(
    rt,
    useMemo(() => cardOf(info), [info]),
  );
  // Undefined while the family's code loads (the tile shows its state meanwhile).
  const mod = useController(info.kind);
  const alarm = mostSevereAlarm(s.alarms.filter((a) => !a.acknowledged));
  const shown = shownState(s.activity, s.alarms);
  // The job in the words of every view: the server's record first (fleet/job-facts.ts).
  const job = useJobWords(info.id, s.job);
  const Extra = mod?.TileExtra;
  const nameId = useId();
  const preloadFirstTab = () =>
    preloadViews([MachinePage, ...(mod?.tabs.slice(0, 1).map((t) => t.Component) ?? [])]);
  // One link per tile, the machine's name; it covers the tile for the pointer (CSS), and any
  // control on the tile sits above it. No clickable <article>.
  return (
    <article
      className={`tile activity-${shown.activity}${alarm?.severity === 'critical' ? ' has-critical' : ''}`}
      data-testid={`tile-${info.id}`}
      data-activity={shown.activity}
      aria-labelledby={nameId}
    >
      <header>
        <div>
          <h3 id={nameId}>
            <Link
              to={`/m/${encodeURIComponent(info.id)}`}
              className="tile-name"
              // The machine page and its first tab are chunks: fetched as the finger or pointer comes.
              onPointerEnter={preloadFirstTab}
              onFocus={preloadFirstTab}
              onTouchStart={preloadFirstTab}
            >
              {info.name}
            </Link>
          </h3>
          <div className="ui-muted small">
            {familyLabel(info.kind)}
            {info.group && (
              <span className="tile-group" data-testid="tile-group">
                {' · '}
                {info.group}
              </span>
            )}
            {info.simulated && (
              <Badge tone="warn" plain title="This machine is simulated: nothing real moves">
                simulated
              </Badge>
            )}
          </div>
        </div>
        <Badge tone={shown.tone} testId="tile-activity">
          {shown.words}
        </Badge>
      </header>
      <div className="tile-label" data-testid="tile-label">
        {s.activityLabel}
      </div>
      {s.job && job ? (
        <div className="tile-job" data-testid="tile-job">
          <div className="tile-job-name" title={job.name} data-testid="tile-job-name">
            {job.name}
          </div>
          <ProgressBar value={job.fraction} label={`${info.name} job progress`} />
          <div className="ui-row small ui-muted tile-job-times">
            <span data-testid="tile-job-percent">{job.percent}</span>
            <span data-testid="tile-job-running">{job.runningFor}</span>
            <span data-testid="tile-job-remaining">{job.remaining}</span>
          </div>
        </div>
      ) : (
        <div className="tile-job ui-muted small">No job</div>
      )}
      {alarm && (
        <div
          className={`tile-alarm tone-${alarm.severity === 'critical' ? 'bad' : alarm.severity === 'warning' ? 'warn' : 'info'}`}
          data-testid="tile-alarm"
        >
          {alarm.severity === 'critical' && <span aria-hidden="true">⚠ </span>}
          {alarm.message}
        </div>
      )}
      {Extra && rt.session && (
        <div className="tile-extra">
          {/* A family's tile extra may be a chunk of its own: nothing shows while it loads. */}
          <Suspense fallback={null}>
            <Extra session={rt.session} />
          </Suspense>
        </div>
      )}
      <footer className="ui-row small">
        <Badge tone={LINK_TONE[s.link]} testId="tile-link" title={s.problem?.message}>
          {linkWords(s.link)}
        </Badge>
        <MachineAge rt={rt} />
      </footer>
      {s.problem && s.link !== 'online' && s.problem.message !== s.activityLabel && (
        <div className="tile-problem small" title={s.problem.message}>
          {s.problem.message}
        </div>
      )}
    </article>
  );
}
