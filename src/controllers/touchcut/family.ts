import type { NodeFamily } from '../../fleet/server-part';
import { touchcutDeclaration } from './declaration';
import { createTouchcutSimulator } from './sim/simulator';

export { touchcutGateway } from './declaration';

/**
 * The Kinetic TouchCut family as Node sees it: its declaration and the simulator. The gateway
 * and `npm run sim` import it; the browser imports `declaration.ts` only (no simulator in the page).
 */
export const touchcutFamily: NodeFamily = {
  ...touchcutDeclaration,
  demo: [{ id: 'demo-touchcut', name: 'Plasma table — TouchCut' }],
  createSimulator: createTouchcutSimulator,
};
