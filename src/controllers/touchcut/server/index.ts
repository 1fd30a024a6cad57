import type { FamilyServerPart } from '../../../fleet/server-part';
import { TouchcutStatsPuller } from './stats-pull';

/**
 * The TouchCut family's server part (Node-only; the page never imports it): its daily production
 * statistics, pulled into the production history (gateway/history/).
 */
export const touchcutServer: FamilyServerPart = {
  history: {
    statsPuller: (o) => new TouchcutStatsPuller(o),
    statsExport: { route: 'touchcut-stats', module: new URL('./stats-export.ts', import.meta.url).href },
  },
};
