import { defineController } from '../../fleet/contract';
import { XtoolSession } from './session';
import { TileExtra } from './views/TileExtra';
import { lazyView } from '../../fleet/lazy';

const Console = lazyView(() => import('./views/Console'), 'Console');
const Files = lazyView(() => import('./views/Files'), 'Files');
const Firmware = lazyView(() => import('./views/Firmware'), 'Firmware');
const Overview = lazyView(() => import('./views/Overview'), 'Overview');
const Safety = lazyView(() => import('./views/Safety'), 'Safety');

/** The browser side of the xTool D-series family: session, tabs, fleet tile extra (its "Find lasers" page is in its manifest). */
export const xtoolModule = defineController<XtoolSession>({
  kind: 'xtool',
  // The manifest's label (a test keeps them equal): importing the manifest here would split it
  // from the shell into a chunk of its own, on every first screen.
  label: 'xTool D-series',
  createSession: (ctx) => new XtoolSession(ctx),
  tabs: [
    { id: 'overview', label: 'Status', Component: Overview },
    { id: 'files', label: 'Files', Component: Files },
    { id: 'safety', label: 'Safety & settings', Component: Safety },
    { id: 'console', label: 'Console', Component: Console, role: 'supervisor' },
    { id: 'firmware', label: 'Firmware', Component: Firmware, role: 'supervisor' },
  ],
  TileExtra,
});
