import type { FamilyDescriptor } from '../../fleet/contract';
import { xtoolDeclaration } from './declaration';
import { createXtoolSimulator } from './sim/simulator';

/**
 * The xTool D-series family as Node sees it: its declaration and the simulator. The gateway and
 * `npm run sim` import it; the browser imports `declaration.ts` only (no simulator in the page).
 */
export const xtoolFamily: FamilyDescriptor = {
  ...xtoolDeclaration,
  createSimulator: createXtoolSimulator,
};
