import type { FamilyDescriptor } from '../fleet/contract';
import type { MachineKind } from '../fleet/types';
import { duetFamily } from './duet/family';
import { g2coreFamily } from './g2core/family';
import { pruntFamily } from './prunt/family';
import { touchcutFamily } from './touchcut/family';
import { xtoolFamily } from './xtool/family';

/**
 * Node-safe list of families: access rules, gateway hints, simulators. Used by the gateway and
 * `npm run sim`, never by the browser (it would bring every simulator into the page; the page's
 * modules spread each family's `declaration.ts`). Add a family here and in `index.ts`.
 */
export const families: Record<MachineKind, FamilyDescriptor> = {
  touchcut: touchcutFamily,
  g2core: g2coreFamily,
  duet: duetFamily,
  xtool: xtoolFamily,
  prunt: pruntFamily,
};
