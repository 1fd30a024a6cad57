import { StrictMode } from 'react';
import { createRoot } from 'react-dom/client';
import '../ui/theme.css';
import './app.css';
import { App } from './App';
import { boot } from './boot';
import { ConsoleUnreachable } from './pwa/ConsoleUnreachable';
import { pwaWanted } from './pwa/wanted';

const root = createRoot(document.getElementById('root') as HTMLElement);
root.render(
  <StrictMode>
    <App />
    <ConsoleUnreachable />
  </StrictMode>,
);
void boot();
// The service worker (installable app, offline shell): production builds in a secure context only.
if (pwaWanted())
  import('./pwa/register').then(
    (m) => m.registerPwa(),
    (e: unknown) => console.warn('Shopdeck: the service worker code did not load', e),
  );
