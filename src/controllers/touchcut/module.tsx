import { defineController } from '../../fleet/contract';
import { TouchcutSession } from './session';
import './views/touchcut.css';
import { lazyView } from '../../fleet/lazy';

const ProgramsView = lazyView(() => import('./views/DataViews'), 'ProgramsView');
const UnloaderView = lazyView(() => import('./views/DataViews'), 'UnloaderView');
const MonitorView = lazyView(() => import('./views/MonitorView'), 'MonitorView');
const StatsView = lazyView(() => import('./views/StatsView'), 'StatsView');
const StatusView = lazyView(() => import('./views/Overview'), 'StatusView');
const ScreenView = lazyView(() => import('./views/ScreenView'), 'ScreenView');
// The tile's thumbnail and the login form: chunks of their own, loaded where they show.
const ScreenThumbnail = lazyView(() => import('./views/ScreenView'), 'ScreenThumbnail');
const LoginForm = lazyView(() => import('./views/LoginForm'), 'LoginForm');

/**
 * Kinetic TouchCut: status, monitor, production statistics, programs, unloader and the live
 * screen. The REST API is read-only, so there are no machine controls here (only the TouchCut
 * user's own password change).
 */
export const touchcutModule = defineController<TouchcutSession>({
  kind: 'touchcut',
  // The manifest's label (a test keeps them equal): importing the manifest here would split it
  // from the shell into a chunk of its own, on every first screen.
  label: 'Kinetic TouchCut',
  createSession: (ctx) => new TouchcutSession(ctx),
  tabs: [
    { id: 'status', label: 'Status', Component: StatusView },
    { id: 'screen', label: 'Screen', Component: ScreenView },
    { id: 'monitor', label: 'Monitor', Component: MonitorView },
    { id: 'stats', label: 'Statistics', Component: StatsView },
    { id: 'programs', label: 'Programs', Component: ProgramsView },
    { id: 'unloader', label: 'Unloader', Component: UnloaderView },
  ],
  TileExtra: ScreenThumbnail,
  LoginForm,
});
