import { defineController } from '../../fleet/contract';
import { DuetSession } from './session';
import { lazyView } from '../../fleet/lazy';

const Console = lazyView(() => import('./views/Console'), 'Console');
const Files = lazyView(() => import('./views/Files'), 'Files');
const HeightMap = lazyView(() => import('./views/HeightMap'), 'HeightMap');
const Overview = lazyView(() => import('./views/Overview'), 'Overview');
const Plugins = lazyView(() => import('./views/Plugins'), 'Plugins');
// The tile's thumbnail and the login form: chunks of their own, loaded where they show.
const TileExtra = lazyView(() => import('./views/Tile'), 'TileExtra');
const LoginForm = lazyView(() => import('./views/Login'), 'LoginForm');

export const duetModule = defineController<DuetSession>({
  kind: 'duet',
  // The manifest's label (a test keeps them equal): importing the manifest here would split it
  // from the shell into a chunk of its own, on every first screen.
  label: 'Duet (RepRapFirmware)',
  createSession: (ctx) => new DuetSession(ctx),
  tabs: [
    { id: 'overview', label: 'Status', Component: Overview },
    { id: 'console', label: 'Console', Component: Console },
    { id: 'files', label: 'Files', Component: Files },
    { id: 'heightmap', label: 'Height map', Component: HeightMap },
    { id: 'plugins', label: 'Plugins', Component: Plugins, role: 'supervisor' },
  ],
  TileExtra,
  LoginForm,
});
