import type { NodeFamily } from '../fleet/server-part';
import type { MachineKind } from '../fleet/types';
import { duetFamily } from './duet/family';
import { g2coreFamily } from './g2core/family';
import { g2coreServer } from './g2core/server';
import { pruntFamily } from './prunt/family';
import { touchcutFamily } from './touchcut/family';
import { touchcutServer } from './touchcut/server';
import { xtoolFamily } from './xtool/family';
import { xtoolServer } from './xtool/server';

/**
 * Node-safe list of families: access rules, gateway hints, simulators, and each family's server
 * part (`<kind>/server/`: a serial bridge, routes, a history pull). Used by the gateway and
 * `npm run sim`, never by the browser (it would bring every simulator and server part into the
 * page; the page's modules spread each family's `declaration.ts`). Add a family here and in
 * `index.ts`. Their order is the built-in demo fleet's (gateway/machines.ts) and `npm run sim`'s.
 */
export const families: Record<MachineKind, NodeFamily> = {
  xtool: { ...xtoolFamily, server: xtoolServer },
  touchcut: { ...touchcutFamily, server: touchcutServer },
  duet: duetFamily,
  prunt: pruntFamily,
  g2core: { ...g2coreFamily, server: g2coreServer },
};
