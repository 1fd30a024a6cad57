import './zod-config';
import { StrictMode } from 'react';
import { createRoot } from 'react-dom/client';
import '../ui/theme.css';
import './app.css';
import { App } from './App';
import { boot } from './boot';
import { ConsoleUnreachable } from './pwa/ConsoleUnreachable';

const root = createRoot(document.getElementById('root') as HTMLElement);
root.render(
  <StrictMode>
    <App />
    <ConsoleUnreachable />
  </StrictMode>,
);
void boot();
