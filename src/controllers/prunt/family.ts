import type { FamilyDescriptor } from '../../fleet/contract';
import { pruntAccess } from './access';
import { createPruntSimulator } from './sim/sim';

/**
 * Node-safe part of the Prunt family (no React, no views, no CSS): the gateway imports it.
 * The simulator speaks the module API (the document's) unless the machine id mentions "flat"
 * or "2025", which gives the deployed 2025 flat API with its exact fixtures.
 */
export const pruntFamily: FamilyDescriptor = {
  kind: 'prunt',
  label: 'Prunt',
  access: pruntAccess,
  gateway: {
    // Pictures in the schema's help texts (`<image src="extras/images/stepper_1.png">`).
    imageAnswer: (path) => /^\/extras\/images\/[^/]+\.(png|jpe?g|gif|webp)$/i.test(path),
  },
  createSimulator: (opts) =>
    createPruntSimulator({ ...opts, api: /flat|2025/.test(opts.id) ? 'flat' : 'module' }),
};
