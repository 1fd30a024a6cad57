import type { FamilyDescriptor } from '../../fleet/contract';
import type { SimOptions, Simulator } from '../../fleet/sim';
import { duetDeclaration } from './declaration';
import { createDuetSimulator } from './sim/simulator';
import { createRrfSimulator } from './sim/standalone';

/**
 * The Duet family as Node sees it: its declaration and the simulator (DSF, or standalone
 * RepRapFirmware for a machine whose `api` is `standalone`). The gateway and `npm run sim` import
 * it; the browser imports `declaration.ts` only (no simulator in the page).
 */
export const duetFamily: FamilyDescriptor = {
  ...duetDeclaration,
  createSimulator: (opts: SimOptions): Simulator =>
    opts.machineApi === 'standalone' ? createRrfSimulator(opts) : createDuetSimulator(opts),
};
