import type { NodeFamily } from '../../fleet/server-part';
import { g2coreDeclaration } from './declaration';
import { createG2coreSimulator } from './sim/simulator';

/**
 * The g2core family as Node sees it: its declaration and the simulator. The gateway and
 * `npm run sim` import it; the browser imports `declaration.ts` only (no simulator in the page).
 */
export const g2coreFamily: NodeFamily = {
  ...g2coreDeclaration,
  demo: [{ id: 'demo-g2core', name: 'CNC router — g2core' }],
  machineFields: ['serial'],
  createSimulator: createG2coreSimulator,
};
