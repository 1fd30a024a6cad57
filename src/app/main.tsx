import { StrictMode } from 'react';
import { createRoot } from 'react-dom/client';
import '../ui/theme.css';
import './app.css';
import { App } from './App';
import { boot } from './boot';
import { afterFirstScreen } from './first-screen';
import { ConsoleUnreachable } from './pwa/ConsoleUnreachable';
import { pwaWanted } from './pwa/wanted';

// The theme chosen on this device (the top bar's picker), before the first paint: no flash, and a
// kiosk tablet, which has no top bar, keeps it too.
const theme = localStorage.getItem('shopdeck.theme');
if (theme === 'light' || theme === 'dark') document.documentElement.setAttribute('data-theme', theme);

const root = createRoot(document.getElementById('root') as HTMLElement);
root.render(
  <StrictMode>
    <App />
    <ConsoleUnreachable />
  </StrictMode>,
);
void boot();
// The service worker (installable app, offline shell): production builds in a secure context
// only, once the first screen is up.
if (pwaWanted())
  afterFirstScreen(() => {
    import('./pwa/register').then(
      (m) => m.registerPwa(),
      (e: unknown) => console.warn('Shopdeck: the service worker code did not load', e),
    );
  });
