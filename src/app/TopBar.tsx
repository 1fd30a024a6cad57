import { useEffect, useState } from 'react';
import { familyPages } from '../controllers';
import { AuthMenu } from './auth/UserControls';
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

/**
 * The console's top bar: the brand, the main pages, the theme and the user menu. A chunk of its own,
 * loaded with the first page (a kiosk tablet shows none).
 */
export function TopBar({ route, activeAlarms }: { route: string; activeAlarms: number }) {
  const [theme, setTheme] = useTheme();
  return (
    <header className="topbar">
      <Link to="/" className="brand" aria-label="Shopdeck fleet">
        <img src="/favicon.svg" alt="" width={26} height={26} />
        Shopdeck
      </Link>
      <nav className="topnav" aria-label="Main">
        <Link to="/" className={route === 'fleet' ? 'active' : ''}>
          Fleet
        </Link>
        <Link to="/alarms" className={route === 'alarms' ? 'active' : ''} data-testid="nav-alarms">
          Alarms
          {activeAlarms > 0 && (
            <span className="nav-count" aria-label={`${activeAlarms} unacknowledged`}>
              {activeAlarms}
            </span>
          )}
        </Link>
        <Link to="/history" className={route === 'history' ? 'active' : ''}>
          History
        </Link>
        <Link to="/audit" className={route === 'audit' ? 'active' : ''}>
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
  );
}
