import { defineController } from '../../fleet/contract';
import { pruntDeclaration } from './declaration';
import { PruntSession } from './session';
import { ConfigTab } from './views/ConfigTab';
import { ConsoleTab } from './views/ConsoleTab';
import { FilesTab } from './views/FilesTab';
import { OverviewTab } from './views/OverviewTab';
import { StatusTab } from './views/StatusTab';

/** The machine page adds the Log tab (the machine log carries the controller's Log lines). */
export const pruntModule = defineController<PruntSession>({
  ...pruntDeclaration,
  createSession: (ctx) => new PruntSession(ctx),
  tabs: [
    { id: 'overview', label: 'Overview', Component: OverviewTab },
    { id: 'status', label: 'Status', Component: StatusTab },
    { id: 'config', label: 'Config', Component: ConfigTab },
    { id: 'files', label: 'Files', Component: FilesTab },
    { id: 'console', label: 'G-code', Component: ConsoleTab, role: 'supervisor' },
  ],
});
