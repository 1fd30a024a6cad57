import { useEffect, useRef, useState } from 'react';
import { useStore } from 'zustand';
import { familyPages } from '../controllers';
import { authStore } from '../fleet/auth';
import { estopConfirmDefault, setEstopConfirm, useEstopConfirm } from '../fleet/estop-confirm';
import { Badge, Button } from '../ui';
import { logout, sessionExtra } from './auth/api';
import { PinUnlock } from './auth/UserControls';
import { Link } from './router';

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

const MENU_ID = 'topbar-menu';

/** The main pages: in the bar, and in the menu on a phone (where the bar has no room for them). */
function PageLinks(props: { route: string; activeAlarms: number; inMenu?: boolean; onPick?: () => void }) {
  const { route, activeAlarms, inMenu, onPick } = props;
  const at = (name: string) => (route === name ? 'page' : undefined);
  return (
    <>
      <Link to="/" aria-current={at('fleet')} onClick={onPick}>
        Fleet
      </Link>
      <Link
        to="/alarms"
        aria-current={at('alarms')}
        onClick={onPick}
        data-testid={inMenu ? undefined : 'nav-alarms'}
      >
        Alarms
        {activeAlarms > 0 && (
          <span className="nav-count">
            {activeAlarms}
            <span className="sr-only"> unacknowledged</span>
          </span>
        )}
      </Link>
      <Link to="/history" aria-current={at('history')} onClick={onPick}>
        History
      </Link>
    </>
  );
}

/**
 * The console's top bar, one row on a 1024 px tablet: the brand, the main pages (Fleet, Alarms,
 * History, the current one `aria-current`), an operator's supervisor unlock (a compact chip while
 * unlocked), and one menu with the rest: who is signed in, the theme, the supervisors' pages (the
 * audit log, finding lasers; not offered to those the gateway refuses them to), sign out. On a
 * phone the main pages move into the menu. A chunk of its own, loaded with the first page (a kiosk
 * tablet shows none).
 */
export function TopBar({ route, activeAlarms }: { route: string; activeAlarms: number }) {
  const [theme, setTheme] = useTheme();
  const mode = useStore(authStore, (s) => s.mode);
  const user = useStore(authStore, (s) => s.user);
  const elevation = useStore(sessionExtra, (s) => s.elevation);
  // What the gateway lets a supervisor (or anyone, in open mode) see: the rest are refused it.
  const supervisor = mode === 'open' || user?.role === 'supervisor' || elevation !== null;
  const menu = useRef<HTMLDivElement>(null);
  const close = () => {
    // A browser without popovers (a test's DOM) has nothing to close.
    const m = menu.current;
    if (typeof m?.hidePopover === 'function') m.hidePopover();
  };
  // A new page closes the menu (back, forward, a shortcut).
  useEffect(() => close(), [route]);
  const at = (name: string) => (route === name ? 'page' : undefined);
  return (
    <header className="topbar">
      <Link to="/" className="brand" aria-label="Shopdeck fleet">
        <img src="/favicon.svg" alt="" width={26} height={26} />
        <span className="brand-name">Shopdeck</span>
      </Link>
      <nav className="topnav" aria-label="Main">
        <PageLinks route={route} activeAlarms={activeAlarms} />
      </nav>
      <div className="topbar-right">
        <PinUnlock compact />
        <button
          type="button"
          className="ui-button secondary topbar-menu-button"
          popoverTarget={MENU_ID}
          data-testid="topbar-menu-button"
        >
          {mode === 'secured' && user ? (
            <>
              <span className="topbar-user">{elevation ? elevation.operator : user.name}</span>
              <Badge
                tone={user.role === 'supervisor' ? 'paused' : user.role === 'operator' ? 'info' : 'muted'}
                plain
                testId="user-role"
              >
                {user.role}
              </Badge>
            </>
          ) : (
            'Menu'
          )}
          {activeAlarms > 0 && (
            <span className="nav-count topbar-menu-count" aria-hidden="true">
              {activeAlarms}
            </span>
          )}
          <span aria-hidden="true" className="topbar-caret">
            ▾
          </span>
        </button>
      </div>
      <div id={MENU_ID} ref={menu} popover="auto" className="topbar-menu" data-testid="topbar-menu">
        <nav className="menu-pages" aria-label="Pages">
          <PageLinks route={route} activeAlarms={activeAlarms} inMenu onPick={close} />
        </nav>
        {supervisor && (
          <nav className="menu-links" aria-label="Supervisor">
            <Link to="/audit" aria-current={at('audit')} onClick={close}>
              Audit log
            </Link>
            {familyPages.map((p) => (
              <Link
                key={`${p.kind}/${p.path}`}
                to={`/${p.kind}/${p.path}`}
                aria-current={
                  route === 'family-page' && location.pathname === `/${p.kind}/${p.path}` ? 'page' : undefined
                }
                onClick={close}
              >
                {p.label}
              </Link>
            ))}
          </nav>
        )}
        <label className="theme-pick">
          <span>Theme</span>
          <select
            className="ui-input"
            value={theme}
            onChange={(e) => setTheme(e.target.value as ThemeChoice)}
          >
            <option value="system">System</option>
            <option value="light">Light</option>
            <option value="dark">Dark</option>
          </select>
        </label>
        <EstopConfirmSwitch />
        {mode === 'secured' &&
          (user ? (
            <Button onClick={() => void logout().then(() => location.assign('/login'))}>Sign out</Button>
          ) : (
            <a href="/login">Sign in</a>
          ))}
      </div>
    </header>
  );
}

/**
 * This console's emergency-stop question (src/fleet/estop-confirm.ts): a switch in the menu, kept
 * in this browser; on by default on touch screens. Every emergency stop and big STOP follows it.
 */
function EstopConfirmSwitch() {
  const on = useEstopConfirm();
  const touchDefault = estopConfirmDefault();
  return (
    <label className="menu-switch" data-testid="estop-confirm-setting">
      <input
        type="checkbox"
        role="switch"
        checked={on}
        aria-checked={on}
        onChange={(e) => setEstopConfirm(e.target.checked)}
        data-testid="estop-confirm-switch"
      />
      <span>
        Ask before an emergency stop on this screen
        <span className="small ui-muted menu-switch-hint">
          {on
            ? 'On: an emergency stop or STOP asks first.'
            : 'Off: an emergency stop or STOP is sent at the first tap.'}{' '}
          Kept on this screen only{touchDefault ? ' (on by default on touch screens)' : ''}.
        </span>
      </span>
    </label>
  );
}
