import { defineController } from '../../fleet/contract';
import { duetDeclaration } from './declaration';
import { DuetSession } from './session';
import { Console } from './views/Console';
import { Files } from './views/Files';
import { HeightMap } from './views/HeightMap';
import { LoginForm } from './views/Login';
import { Overview } from './views/Overview';
import { Plugins } from './views/Plugins';
import { TileExtra } from './views/Tile';

export const duetModule = defineController<DuetSession>({
  ...duetDeclaration,
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
