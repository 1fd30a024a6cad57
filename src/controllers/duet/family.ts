import type { NodeFamily } from '../../fleet/server-part';
import type { SimOptions, Simulator } from '../../fleet/sim';
import { duetDeclaration } from './declaration';
import { duetHeldSessionFor, type DuetApiState } from './gateway';
import { duetSharingFor } from './sharing';
import { createDuetSimulator } from './sim/simulator';
import { createRrfSimulator } from './sim/standalone';

/**
 * The Duet family as Node sees it: its declaration and the simulator (DSF, or standalone
 * RepRapFirmware for a machine whose `api` is `standalone`). The gateway and `npm run sim` import
 * it; the browser imports `declaration.ts` only (no simulator in the page).
 */
export const duetFamily: NodeFamily = {
  ...duetDeclaration,
  demo: [
    { id: 'demo-duet', name: 'Printer bay — Duet 3' },
    { id: 'demo-duet-standalone', name: 'Printer bay — Duet 2 (standalone)', api: 'standalone' },
  ],
  machineFields: ['api'],
  simVariants: [
    { id: 'sim-duet-standalone', label: 'Duet (standalone RepRapFirmware, rr_*)', machineApi: 'standalone' },
  ],
  gateway: {
    ...duetDeclaration.gateway,
    /**
     * Per machine: DSF or standalone (`rr_*`), learned by the held session's probe (or the
     * machines file's `api`) and then followed by the sharing (limits, watch). Built on `this`,
     * so a declaration that replaces `session` or `sharing` keeps its replacements. Node only
     * (the gateway): the page learns the API from the connect answer.
     */
    forMachine(m) {
      const state: DuetApiState = { api: m.api ?? null };
      return {
        session: duetHeldSessionFor(state, this.session),
        sharing: duetSharingFor(state, this.sharing),
      };
    },
  },
  createSimulator: (opts: SimOptions): Simulator =>
    opts.machineApi === 'standalone' ? createRrfSimulator(opts) : createDuetSimulator(opts),
};
