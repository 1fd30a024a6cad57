import { defineController } from '../../fleet/contract';
import { G2coreSession } from './session';
import './views/g2core.css';
import { G2coreTile } from './views/Tile';
import { lazyView } from '../../fleet/lazy';

const ConsoleTab = lazyView(() => import('./views/Console'), 'ConsoleTab');
const JobsTab = lazyView(() => import('./views/Jobs'), 'JobsTab');
const JogTab = lazyView(() => import('./views/Jog'), 'JogTab');
const OverviewTab = lazyView(() => import('./views/Overview'), 'OverviewTab');
const SettingsTab = lazyView(() => import('./views/Settings'), 'SettingsTab');

/** The g2core controller module: session, tabs. The machine page adds Log and Simulator tabs. */
export const g2coreModule = defineController<G2coreSession>({
  kind: 'g2core',
  // The manifest's label (a test keeps them equal): importing the manifest here would split it
  // from the shell into a chunk of its own, on every first screen.
  label: 'g2core CNC',
  createSession: (ctx) => new G2coreSession(ctx),
  tabs: [
    { id: 'overview', label: 'Status', Component: OverviewTab },
    { id: 'jog', label: 'Jog & home', Component: JogTab, role: 'operator' },
    { id: 'jobs', label: 'Jobs', Component: JobsTab },
    { id: 'console', label: 'Console', Component: ConsoleTab, role: 'supervisor' },
    { id: 'settings', label: 'Settings', Component: SettingsTab, role: 'supervisor' },
  ],
  TileExtra: G2coreTile,
});
