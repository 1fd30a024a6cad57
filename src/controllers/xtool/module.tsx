import { defineController } from '../../fleet/contract';
import { FAMILY_LABELS } from '../labels';
import { XtoolSession } from './session';
import { TileExtra } from './views/TileExtra';
import { lazyView } from '../../fleet/lazy';

const Console = lazyView(() => import('./views/Console'), 'Console');
const Files = lazyView(() => import('./views/Files'), 'Files');
const Firmware = lazyView(() => import('./views/Firmware'), 'Firmware');
const Overview = lazyView(() => import('./views/Overview'), 'Overview');
const Safety = lazyView(() => import('./views/Safety'), 'Safety');

/** The browser side of the xTool D-series family: session, tabs, fleet tile extra (its "Find lasers" page is listed in ../index.ts). */
export const xtoolModule = defineController<XtoolSession>({
  kind: 'xtool',
  label: FAMILY_LABELS.xtool,
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
