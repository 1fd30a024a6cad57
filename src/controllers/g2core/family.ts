import type { FamilyDescriptor } from '../../fleet/contract';
import { g2coreAccess, g2coreAccessNeedsBody } from './access';
import { createG2coreSimulator } from './sim/simulator';

/**
 * The Node-safe part of the g2core family: access rules, simulator. No React, views or CSS here:
 * the gateway imports this file in Node. No gateway hints: the REST design has no secrets and
 * no WebSocket.
 */
export const g2coreFamily: FamilyDescriptor = {
  kind: 'g2core',
  label: 'g2core CNC (REST)',
  access: g2coreAccess,
  accessNeedsBody: g2coreAccessNeedsBody,
  createSimulator: createG2coreSimulator,
};
