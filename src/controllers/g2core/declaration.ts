import type { FamilyDeclaration } from '../../fleet/contract';
import { g2coreAccess, g2coreAccessNeedsBody } from './access';

/**
 * The Node-safe declaration of the g2core family: access rules. No React, views, CSS or simulator
 * here: the gateway and the browser import this file. No gateway hints: the REST design has no
 * secrets and no WebSocket.
 */
export const g2coreDeclaration: FamilyDeclaration = {
  kind: 'g2core',
  label: 'g2core CNC (REST)',
  access: g2coreAccess,
  accessNeedsBody: g2coreAccessNeedsBody,
};
