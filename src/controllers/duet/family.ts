import type { FamilyDescriptor } from '../../fleet/contract';
import { duetAccess, duetAccessNeedsBody } from './access';
import { duetHeldSession } from './gateway';
import { createDuetSimulator } from './sim/simulator';

/**
 * Node-safe part of the Duet (DSF) family: access rules, gateway hints and the simulator. No
 * React, views or CSS here — the gateway imports it.
 */
export const duetFamily: FamilyDescriptor = {
  kind: 'duet',
  label: 'Duet (DSF)',
  access: duetAccess,
  accessNeedsBody: duetAccessNeedsBody,
  gateway: {
    /**
     * The gateway holds the DSF session (`gateway.ts`): it connects with the machine's password
     * (or one a user typed into the login form) and keeps the key; browsers never get it.
     */
    session: duetHeldSession,
  },
  createSimulator: createDuetSimulator,
};
