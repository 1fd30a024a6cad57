import { defineController } from '../../fleet/contract';
import { FAMILY_LABELS } from '../labels';
import { PruntSession } from './session';
import { lazyView } from '../../fleet/lazy';

const ConfigTab = lazyView(() => import('./views/ConfigTab'), 'ConfigTab');
const ConsoleTab = lazyView(() => import('./views/ConsoleTab'), 'ConsoleTab');
const FilesTab = lazyView(() => import('./views/FilesTab'), 'FilesTab');
const OverviewTab = lazyView(() => import('./views/OverviewTab'), 'OverviewTab');
const StatusTab = lazyView(() => import('./views/StatusTab'), 'StatusTab');

/** The machine page adds the Log tab (the machine log carries the controller's Log lines). */
export const pruntModule = defineController<PruntSession>({
  kind: 'prunt',
  label: FAMILY_LABELS.prunt,
  createSession: (ctx) => new PruntSession(ctx),
  tabs: [
    { id: 'overview', label: 'Status', Component: OverviewTab },
    { id: 'status', label: 'Readings', Component: StatusTab },
    { id: 'config', label: 'Config', Component: ConfigTab },
    { id: 'files', label: 'Files', Component: FilesTab },
    { id: 'console', label: 'Console', Component: ConsoleTab, role: 'supervisor' },
  ],
});
