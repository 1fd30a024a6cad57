import type { FamilyDescriptor } from '../../fleet/contract';
import { xtoolAccess } from './access';
import { createXtoolSimulator } from './sim/simulator';

/**
 * The Node-safe part of the xTool D-series family: access rules, gateway hints, simulator.
 * No React, views or CSS here: the gateway imports this file in Node.
 */
export const xtoolFamily: FamilyDescriptor = {
  kind: 'xtool',
  label: 'xTool D-series',
  access: xtoolAccess,
  gateway: {
    // The status WebSocket is on :8081 of the same host (document, "TCP Ports"); the client
    // opens `/machines/<id>/`, i.e. the root path of the device's :8081.
    defaultWsPort: 8081,
  },
  createSimulator: createXtoolSimulator,
};
