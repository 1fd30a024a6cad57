import { defineController } from '../../fleet/contract';
import { xtoolDeclaration } from './declaration';
import { XtoolSession } from './session';
import { Console } from './views/Console';
import { Discover } from './views/Discover';
import { Files } from './views/Files';
import { Firmware } from './views/Firmware';
import { Overview } from './views/Overview';
import { Safety } from './views/Safety';
import { TileExtra } from './views/TileExtra';

/** The browser side of the xTool D-series family: session, tabs, fleet tile extra, "Find lasers". */
export const xtoolModule = defineController<XtoolSession>({
  ...xtoolDeclaration,
  createSession: (ctx) => new XtoolSession(ctx),
  tabs: [
    { id: 'overview', label: 'Status', Component: Overview },
    { id: 'files', label: 'Files', Component: Files },
    { id: 'safety', label: 'Safety & settings', Component: Safety },
    { id: 'console', label: 'G-code', Component: Console, role: 'supervisor' },
    { id: 'firmware', label: 'Firmware', Component: Firmware, role: 'supervisor' },
  ],
  TileExtra,
  pages: [{ path: 'discover', label: 'Find lasers', Component: Discover }],
});
