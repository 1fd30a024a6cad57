import { Suspense, useEffect, useState } from 'react';
import { useStore } from 'zustand';
import { familyPages } from '../controllers';
import { authStore } from '../fleet/auth';
import { EmptyState, Loading } from '../ui';
import { lazyView, whenIdle } from '../fleet/lazy';
import { alarmSummary } from './alarms/summary';
import { AuthMenu } from './auth/UserControls';
import { ErrorBoundary } from './ErrorBoundary';
import { AlarmsPage, AuditPage, FleetPage, HistoryPage, LoginPage, MachinePage, WallPage } from './pages';
import { Link, matchRoute, useLocation } from './router';
import { Shortcuts } from './shortcuts/lazy';

// The alarm layer (banner, modal alert, the list it follows): loaded once the first screen shows.
const AlarmModal = lazyView(() => import('./alarms/layer'), 'AlarmModal');
const AlarmStrip = lazyView(() => import('./alarms/layer'), 'AlarmStrip');

type ThemeChoice = 'system' | 'light' | 'dark';

function useTheme(): [ThemeChoice, (t: ThemeChoice) => void] {
  const [theme, setTheme] = useState<ThemeChoice>(() => {
    const t = localStorage.getItem('shopdeck.theme');
    return t === 'light' || t === 'dark' ? t : 'system';
  });
  useEffect(() => {
    if (theme === 'system') document.documentElement.removeAttribute('data-theme');
    else document.documentElement.setAttribute('data-theme', theme);
    localStorage.setItem('shopdeck.theme', theme);
  }, [theme]);
  return [theme, setTheme];
}

export function App() {
  const { pathname, search } = useLocation();
  const route = matchRoute(pathname, search);
  // Kiosk tablet (`/m/<id>?kiosk`): one machine, nothing to navigate away with (src/app/kiosk/).
  const kiosk = route.name === 'machine' && route.kiosk === true;
  const [theme, setTheme] = useTheme();
  const mode = useStore(authStore, (s) => s.mode);
  const user = useStore(authStore, (s) => s.user);
  const openOnNetwork = useStore(authStore, (s) => s.openOnNetwork === true);
  // The alarm centre on every page, from when the browser is first idle.
  const [alarmsOn, setAlarmsOn] = useState(false);
  useEffect(() => whenIdle(() => setAlarmsOn(true)), []);
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
      body = page ? <page.Component /> : <EmptyState>There is no page here.</EmptyState>;
      break;
    }
    default:
      body = (
        <EmptyState>
          There is no page here. <Link to="/">Back to the fleet</Link>
        </EmptyState>
      );
  }

  return (
    <div className={kiosk ? 'app kiosk' : 'app'}>
      {/* A blocking alarm makes the whole page behind it inert: no click, no focus, no reading. */}
      <div className="app-page" inert={blocking > 0} data-testid="app-page">
        <header className="topbar" hidden={kiosk}>
          <Link to="/" className="brand" aria-label="Shopdeck fleet">
            <img src="/favicon.svg" alt="" width={26} height={26} />
            Shopdeck
          </Link>
          <nav className="topnav" aria-label="Main">
            <Link to="/" className={route.name === 'fleet' ? 'active' : ''}>
              Fleet
            </Link>
            <Link to="/alarms" className={route.name === 'alarms' ? 'active' : ''} data-testid="nav-alarms">
              Alarms
              {activeAlarms > 0 && (
                <span className="nav-count" aria-label={`${activeAlarms} unacknowledged`}>
                  {activeAlarms}
                </span>
              )}
            </Link>
            <Link to="/history" className={route.name === 'history' ? 'active' : ''}>
              History
            </Link>
            <Link to="/audit" className={route.name === 'audit' ? 'active' : ''}>
              Audit
            </Link>
            {familyPages.map((p) => (
              <Link key={`${p.kind}/${p.path}`} to={`/${p.kind}/${p.path}`}>
                {p.label}
              </Link>
            ))}
          </nav>
          <div className="topbar-right">
            <label className="theme-pick">
              <span className="sr-only">Theme</span>
              <select
                className="ui-input"
                value={theme}
                onChange={(e) => setTheme(e.target.value as ThemeChoice)}
                aria-label="Theme"
              >
                <option value="system">Theme: system</option>
                <option value="light">Theme: light</option>
                <option value="dark">Theme: dark</option>
              </select>
            </label>
            <AuthMenu />
          </div>
        </header>
        {alarmsOn && (
          <ErrorBoundary label="Alarms">
            <Suspense fallback={null}>
              <AlarmStrip hideOn={route.name === 'machine' ? route.id : null} kiosk={kiosk} />
            </Suspense>
          </ErrorBoundary>
        )}
        {mode === 'open' && (
          <div className="open-banner" role="note" data-testid="open-mode-banner">
            {openOnNetwork
              ? 'Open mode on the network (SHOPDECK_OPEN=1): anyone who can reach this computer can control these machines. Add users to require a login (see the README).'
              : 'Open mode: no login is needed, and the console only answers on this computer. Add users before serving it to tablets (see the README).'}
          </div>
        )}
        {mode === 'secured' && !user && route.name !== 'login' ? (
          <main className="main">
            <Suspense fallback={<Loading />}>
              <LoginPage />
            </Suspense>
          </main>
        ) : (
          <main className="main">
            <ErrorBoundary label="Page">
              {/* Every page is a chunk of its own (issue 16). */}
              <Suspense fallback={<Loading />}>{body}</Suspense>
            </ErrorBoundary>
          </main>
        )}
      </div>
      {alarmsOn && (
        <ErrorBoundary label="Alarms">
          <Suspense fallback={null}>
            <AlarmModal />
          </Suspense>
        </ErrorBoundary>
      )}
      {/* Keyboard shortcuts (`?` lists them): code of their own, loaded after the first screen. */}
      <Suspense fallback={null}>
        <Shortcuts />
      </Suspense>
    </div>
  );
}
