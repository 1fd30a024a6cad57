import type { NodeFamily } from '../../fleet/server-part';
import { xtoolDeclaration } from './declaration';
import { createXtoolSimulator } from './sim/simulator';

/**
 * The xTool D-series family as Node sees it: its declaration and the simulator. The gateway and
 * `npm run sim` import it; the browser imports `declaration.ts` only (no simulator in the page).
 */
export const xtoolFamily: NodeFamily = {
  ...xtoolDeclaration,
  demo: [{ id: 'demo-xtool', name: 'Laser bay — xTool D1 Pro' }],
  createSimulator: createXtoolSimulator,
};
