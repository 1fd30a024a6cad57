import { defineController } from '../../fleet/contract';
import { FAMILY_LABELS } from '../labels';
import { DuetSession } from './session';
import { LoginForm } from './views/Login';
import { TileExtra } from './views/Tile';
import { lazyView } from '../../fleet/lazy';

const Console = lazyView(() => import('./views/Console'), 'Console');
const Files = lazyView(() => import('./views/Files'), 'Files');
const HeightMap = lazyView(() => import('./views/HeightMap'), 'HeightMap');
const Overview = lazyView(() => import('./views/Overview'), 'Overview');
const Plugins = lazyView(() => import('./views/Plugins'), 'Plugins');

export const duetModule = defineController<DuetSession>({
  kind: 'duet',
  label: FAMILY_LABELS.duet,
  createSession: (ctx) => new DuetSession(ctx),
  tabs: [
    { id: 'overview', label: 'Overview', Component: Overview },
    { id: 'console', label: 'Console', Component: Console },
    { id: 'files', label: 'Files', Component: Files },
    { id: 'heightmap', label: 'Height map', Component: HeightMap },
    { id: 'plugins', label: 'Plugins', Component: Plugins, role: 'supervisor' },
  ],
  TileExtra,
  LoginForm,
});
