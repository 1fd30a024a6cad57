import { Suspense, useEffect, type ComponentType } from 'react';
import { useStore } from 'zustand';
import { familyLabel, useController } from '../controllers';
import { linkWords, type TabProps, type MachineSession } from '../fleet/contract';
import { fleetStore, getRuntime, showDetail, type MachineRuntime } from '../fleet/fleet';
import { lazyView, preloadViews, whenIdle } from '../fleet/lazy';
import { LogView, useRole, useSnapshot } from '../fleet/react';
import { roleAtLeast, type Activity, type Alarm } from '../fleet/types';
import { Badge, EmptyState, Loading, Notice } from '../ui';
import { MachineAge } from './Age';
import { ErrorBoundary } from './ErrorBoundary';
import { JobControls, PendingJobControls } from './kiosk/JobControls';
import { KIOSK_FAMILIES } from './kiosk/per-family';
import { MachineProblems } from './MachineProblems';
import { KioskPage } from './pages';
import { Link, usePageTitle } from './router';
import { LINK_TONE, shownState } from './status';

const SimulatorPanel = lazyView(() => import('./SimulatorPanel'), 'SimulatorPanel');

interface PageTab {
  id: string;
  label: string;
  render: () => React.ReactNode;
}

/** `kiosk`: the machine alone for a tablet at the machine (`/m/<id>?kiosk`, src/app/kiosk/). */
export function MachinePage({ id, tab, kiosk = false }: { id: string; tab: string | null; kiosk?: boolean }) {
  const status = useStore(fleetStore, (s) => s.status);
  const rt = getRuntime(id);
  if (!rt) {
    if (status === 'loading') return <EmptyState>Loading…</EmptyState>;
    return (
      <Notice tone="warn" title="No such machine">
        There is no machine “{id}” in this console.
        {!kiosk && (
          <>
            {' '}
            <Link to="/">Back to the fleet</Link>
          </>
        )}
      </Notice>
    );
  }
  // Keyed by the machine: the page shown for another machine (/m/a, then /m/b) starts afresh,
  // nothing of A's tabs' state or error is B's.
  return (
    <ErrorBoundary key={id} label={rt.info.name}>
      {kiosk ? (
        <Suspense fallback={<Loading />}>
          <KioskPage rt={rt} />
        </Suspense>
      ) : (
        <MachinePageBody rt={rt} tab={tab} />
      )}
    </ErrorBoundary>
  );
}

function MachinePageBody({ rt, tab }: { rt: MachineRuntime; tab: string | null }) {
  const info = rt.info;
  const mod = useController(info.kind);
  const role = useRole();
  const s = useSnapshot(rt, (x) => ({
    link: x.link,
    activity: x.activity,
    activityLabel: x.activityLabel,
    alarms: x.alarms,
    problem: x.problem,
    identity: x.identity,
    retryAt: x.retryAt,
  }));
  const session = rt.session;
  const family = KIOSK_FAMILIES[info.kind];
  const tabs: PageTab[] = [];
  if (mod && session) {
    for (const t of mod.tabs) {
      if (t.role && !roleAtLeast(role, t.role)) continue;
      const C = t.Component as ComponentType<TabProps<MachineSession>>;
      tabs.push({ id: t.id, label: t.label, render: () => <C session={session} /> });
    }
  }
  tabs.push({ id: 'events', label: 'Event log', render: () => <LogView log={rt.log} /> });
  // The simulator runs in the gateway; driving it is for supervisors (gateway/sim-api.ts).
  if (info.simulated && roleAtLeast(role, 'supervisor'))
    tabs.push({ id: 'simulator', label: 'Simulator', render: () => <SimulatorPanel id={info.id} /> });
  const current = tabs.find((t) => t.id === tab) ?? tabs[0];
  usePageTitle(`${info.name} — ${shownState(s.activity, s.alarms).words}`);
  // While this page shows, the machine's detail reads run at full pace (4 Hz positions…).
  useEffect(() => showDetail(info.id), [info.id]);
  // The other tabs' code, when the browser has nothing else to do: a tab switch is instant.
  // After the machine's data shows (the first screen is not slowed by tabs not asked for).
  const shown = s.link === 'online';
  useEffect(
    () => (shown ? whenIdle(() => preloadViews(mod?.tabs.map((t) => t.Component) ?? [])) : undefined),
    [mod, shown],
  );
  const LoginForm = mod?.LoginForm as ComponentType<TabProps<MachineSession>> | undefined;

  return (
    <div className="machine-page" data-testid={`machine-${info.id}`}>
      <div className="machine-head">
        <div>
          <div className="crumbs ui-muted small">
            <Link to="/">Fleet</Link> / {familyLabel(info.kind)}
          </div>
          <h1>{info.name}</h1>
          <div className="ui-muted small">{s.identity ?? info.id}</div>
        </div>
        <div className="machine-state">
          <MachineStateChip activity={s.activity} alarms={s.alarms} />
          <div className="machine-label" data-testid="machine-label">
            {s.activityLabel}
          </div>
          <div className="ui-row small">
            <Badge tone={LINK_TONE[s.link]} testId="machine-link">
              {linkWords(s.link)}
            </Badge>
            <MachineAge rt={rt} testId="machine-data-age" />
          </div>
        </div>
      </div>
      {info.simulated && (
        <div className="sim-banner" role="note" data-testid="simulated-banner">
          Simulated machine: everything on this page comes from a simulator running in the console’s server.
          Nothing real moves.
        </div>
      )}
      <MachineProblems rt={rt} LoginForm={LoginForm} showPath />
      {/* The same job control row as the kiosk's, in every family, above every tab. */}
      {/* While the family's code loads: the same row, disabled, "Connecting…". */}
      {family &&
        (session ? (
          <JobControls session={session} family={family} />
        ) : (
          !rt.error && <PendingJobControls family={family} />
        ))}
      {/* The sections are URLs (bookmarkable): links, the current one marked aria-current. */}
      <nav className="tabs" aria-label="Machine sections">
        {tabs.map((t) => (
          <Link
            key={t.id}
            to={`/m/${encodeURIComponent(info.id)}/${t.id}`}
            replace
            aria-current={t.id === current?.id ? 'page' : undefined}
            className={t.id === current?.id ? 'tab active' : 'tab'}
            data-testid={`tab-${t.id}`}
          >
            {t.label}
          </Link>
        ))}
      </nav>
      <div className="tab-body">
        {/* The family's code is still loading: its tabs come with it. */}
        {!session && !rt.error && tab !== 'events' ? (
          <Loading />
        ) : (
          current && (
            <ErrorBoundary key={current.id} label={`${info.name} · ${current.label}`}>
              {/* A family's tab is its own chunk, loaded when first shown (issue 16). */}
              <Suspense fallback={<Loading />}>{current.render()}</Suspense>
            </ErrorBoundary>
          )
        )}
      </div>
    </div>
  );
}

/** The machine page header's state chip: an unacknowledged critical alarm overrides the activity. */
function MachineStateChip({ activity, alarms }: { activity: Activity; alarms: readonly Alarm[] }) {
  const shown = shownState(activity, alarms);
  return (
    <Badge tone={shown.tone} testId="machine-activity">
      {shown.words}
    </Badge>
  );
}
