import type { NodeFamily } from '../../fleet/server-part';
import { pruntDeclaration } from './declaration';
import { createPruntSimulator } from './sim/sim';

/**
 * The Prunt family as Node sees it: its declaration and the simulator (the gateway and
 * `npm run sim` import it; the browser imports `declaration.ts` only). The simulator speaks the
 * module API (the document's) unless the machine id mentions "flat" or "2025", which gives the
 * deployed 2025 flat API with its exact fixtures.
 */
export const pruntFamily: NodeFamily = {
  ...pruntDeclaration,
  demo: [{ id: 'demo-prunt', name: 'Printer bay — Prunt' }],
  createSimulator: (opts) =>
    createPruntSimulator({ ...opts, api: /flat|2025/.test(opts.id) ? 'flat' : 'module' }),
};
