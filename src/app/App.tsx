import { Suspense, useEffect, useState } from 'react';
import { useStore } from 'zustand';
import { familyPages } from '../controllers';
import { authStore } from '../fleet/auth';
import { EmptyState, Loading } from '../ui';
import { lazyView, preloadViews } from '../fleet/lazy';
import { alarmSummary } from './alarms/summary';
import { ErrorBoundary } from './ErrorBoundary';
import { afterFirstScreen } from './first-screen';
import {
  AlarmsPage,
  AuditPage,
  FleetPage,
  HistoryPage,
  KioskPage,
  LoginPage,
  MachinePage,
  WallPage,
} from './pages';
import { Link, matchRoute, Titled, useLocation } from './router';
import { Shortcuts } from './shortcuts/lazy';

// The alarm layer (banner, modal alert, the list it follows): loaded once the first screen shows.
const AlarmModal = lazyView(() => import('./alarms/layer'), 'AlarmModal');
const AlarmStrip = lazyView(() => import('./alarms/layer'), 'AlarmStrip');
const TopBar = lazyView(() => import('./TopBar'), 'TopBar');

export function App() {
  const { pathname, search } = useLocation();
  const route = matchRoute(pathname, search);
  // Kiosk tablet (`/m/<id>?kiosk`): one machine, nothing to navigate away with (src/app/kiosk/).
  const kiosk = route.name === 'machine' && route.kiosk === true;
  // Both of a kiosk's chunks at once, not the kiosk view after the machine page's.
  if (kiosk) preloadViews([MachinePage, KioskPage]);
  const mode = useStore(authStore, (s) => s.mode);
  const user = useStore(authStore, (s) => s.user);
  const openOnNetwork = useStore(authStore, (s) => s.openOnNetwork === true);
  // The alarm centre on every page, from when the browser is idle after the first screen (the
  // tiles, or the machine in view answering; a few seconds at most).
  const [settled, setSettled] = useState(false);
  useEffect(() => afterFirstScreen(() => setSettled(true)), []);
  const blocking = useStore(alarmSummary, (s) => s.blocking);
  const activeAlarms = useStore(alarmSummary, (s) => s.unacknowledged);

  // The wall screen (a TV): the page alone, read only — no top bar, no controls.
  if (route.name === 'wall')
    return (
      <ErrorBoundary label="Wall screen">
        <Suspense fallback={<Loading />}>
          <WallPage />
        </Suspense>
      </ErrorBoundary>
    );

  let body: React.ReactNode;
  switch (route.name) {
    case 'fleet':
      body = <FleetPage />;
      break;
    case 'machine':
      body = <MachinePage id={route.id} tab={route.tab} kiosk={kiosk} />;
      break;
    case 'audit':
      body = <AuditPage />;
      break;
    case 'alarms':
      body = <AlarmsPage />;
      break;
    case 'history':
      body = <HistoryPage />;
      break;
    case 'login':
      body = <LoginPage />;
      break;
    case 'family-page': {
      const page = familyPages.find((p) => p.kind === route.kind && p.path === route.page);
      body = page ? (
        <Titled title={page.label}>
          <page.Component />
        </Titled>
      ) : (
        <Titled title="No page here">
          <h1 className="sr-only">No page here</h1>
          <EmptyState>There is no page here.</EmptyState>
        </Titled>
      );
      break;
    }
    default:
      body = (
        <Titled title="No page here">
          <h1 className="sr-only">No page here</h1>
          <EmptyState>
            There is no page here. <Link to="/">Back to the fleet</Link>
          </EmptyState>
        </Titled>
      );
  }

  return (
    <div className={kiosk ? 'app kiosk' : 'app'}>
      {/* A blocking alarm makes the whole page behind it inert: no click, no focus, no reading. */}
      <div className="app-page" inert={blocking > 0} data-testid="app-page">
        {/* The first stop of the Tab key: past the top bar, to the page itself. */}
        {!kiosk && (
          <a
            className="skip-link"
            href="#main"
            onClick={(e) => {
              e.preventDefault();
              document.getElementById('main')?.focus();
            }}
          >
            Skip to main content
          </a>
        )}
        {/* The top bar is a chunk of its own: a kiosk tablet never loads it (issue 16). */}
        {!kiosk && (
          <Suspense fallback={<header className="topbar" aria-hidden="true" />}>
            <TopBar route={route.name} activeAlarms={activeAlarms} />
          </Suspense>
        )}
        {settled && (
          <ErrorBoundary label="Alarms">
            <Suspense fallback={null}>
              <AlarmStrip hideOn={route.name === 'machine' ? route.id : null} kiosk={kiosk} />
            </Suspense>
          </ErrorBoundary>
        )}
        {mode === 'open' && (
          <aside className="open-banner" aria-label="Open mode" data-testid="open-mode-banner">
            {openOnNetwork
              ? 'Open mode on the network (SHOPDECK_OPEN=1): anyone who can reach this computer can control these machines. Add users to require a login (see the README).'
              : 'Open mode: no login is needed, and the console only answers on this computer. Add users before serving it to tablets (see the README).'}
          </aside>
        )}
        {mode === 'secured' && !user && route.name !== 'login' ? (
          <main className="main" id="main" tabIndex={-1}>
            <Suspense fallback={<Loading />}>
              <LoginPage />
            </Suspense>
          </main>
        ) : (
          <main className="main" id="main" tabIndex={-1}>
            <ErrorBoundary label="Page">
              {/* Every page is a chunk of its own (issue 16). */}
              <Suspense fallback={<Loading />}>{body}</Suspense>
            </ErrorBoundary>
          </main>
        )}
      </div>
      {settled && (
        <ErrorBoundary label="Alarms">
          <Suspense fallback={null}>
            <AlarmModal kioskMachine={kiosk && route.name === 'machine' ? route.id : null} />
          </Suspense>
        </ErrorBoundary>
      )}
      {/* Keyboard shortcuts (`?` lists them): code of their own, loaded with the page (on a kiosk
          tablet, which has no keyboard as a rule, after its first screen). */}
      {(settled || !kiosk) && (
        <Suspense fallback={null}>
          <Shortcuts />
        </Suspense>
      )}
    </div>
  );
}
