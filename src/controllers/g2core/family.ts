import type { FamilyDescriptor } from '../../fleet/contract';
import { g2coreDeclaration } from './declaration';
import { createG2coreSimulator } from './sim/simulator';

/**
 * The g2core family as Node sees it: its declaration and the simulator. The gateway and
 * `npm run sim` import it; the browser imports `declaration.ts` only (no simulator in the page).
 */
export const g2coreFamily: FamilyDescriptor = {
  ...g2coreDeclaration,
  createSimulator: createG2coreSimulator,
};
