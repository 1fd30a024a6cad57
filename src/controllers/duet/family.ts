import type { FamilyDescriptor } from '../../fleet/contract';
import { duetDeclaration } from './declaration';
import { createDuetSimulator } from './sim/simulator';

/**
 * The Duet (DSF) family as Node sees it: its declaration and the simulator. The gateway and
 * `npm run sim` import it; the browser imports `declaration.ts` only (no simulator in the page).
 */
export const duetFamily: FamilyDescriptor = {
  ...duetDeclaration,
  createSimulator: createDuetSimulator,
};
