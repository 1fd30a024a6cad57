import type { FamilyDescriptor } from '../../fleet/contract';
import { duetAccess, duetAccessNeedsBody } from './access';
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
     * The machine's password goes into `password` of `GET /machine/connect`, replacing whatever the
     * browser sent, when one is configured. Without a configured password the browser's own value
     * (typed into the login form after a 403) is forwarded as it is.
     */
    injectSecrets: (req, secrets) => {
      if (
        req.method.toUpperCase() === 'GET' &&
        req.path.split('?')[0] === '/machine/connect' &&
        secrets.password
      ) {
        req.query.set('password', secrets.password);
      }
    },
  },
  createSimulator: createDuetSimulator,
};
