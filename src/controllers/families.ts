import type { FamilyDescriptor } from '../fleet/contract';
import type { MachineKind } from '../fleet/types';
import { xtoolFamily } from './xtool/family';

/**
 * Node-safe list of families: access rules, gateway hints, simulators. Used by the gateway,
 * `npm run sim` and the browser. Add a family here and in `index.ts`.
 */
export const families: Partial<Record<MachineKind, FamilyDescriptor>> = {
  xtool: xtoolFamily,
};
