import { defineController } from '../../fleet/contract';
import { PruntSession } from './session';
import { lazyView } from '../../fleet/lazy';

const ConfigTab = lazyView(() => import('./views/ConfigTab'), 'ConfigTab');
const ConsoleTab = lazyView(() => import('./views/ConsoleTab'), 'ConsoleTab');
const FilesTab = lazyView(() => import('./views/FilesTab'), 'FilesTab');
const OverviewTab = lazyView(() => import('./views/Overview'), 'OverviewTab');
const StatusTab = lazyView(() => import('./views/StatusTab'), 'StatusTab');

/** The machine page adds the Log tab (the machine log carries the controller's Log lines). */
export const pruntModule = defineController<PruntSession>({
  kind: 'prunt',
  // The manifest's label (a test keeps them equal): importing the manifest here would split it
  // from the shell into a chunk of its own, on every first screen.
  label: 'Prunt',
  createSession: (ctx) => new PruntSession(ctx),
  tabs: [
    { id: 'overview', label: 'Status', Component: OverviewTab },
    { id: 'status', label: 'Readings', Component: StatusTab },
    { id: 'config', label: 'Config', Component: ConfigTab },
    { id: 'files', label: 'Files', Component: FilesTab },
    { id: 'console', label: 'Console', Component: ConsoleTab, role: 'supervisor' },
  ],
});
