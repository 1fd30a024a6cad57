import type { FamilyDeclaration } from '../../fleet/contract';
import { g2coreAccess, g2coreAccessBodyLimit, g2coreAccessNeedsBody } from './access';
import { g2coreSharing } from './sharing';

/**
 * The Node-safe declaration of the g2core family: access rules. No React, views, CSS or simulator
 * here: the gateway and the browser import this file. The REST design has no secrets and no
 * WebSocket: the only gateway hint is how the controller is shared (`sharing.ts`).
 */
export const g2coreDeclaration: FamilyDeclaration = {
  kind: 'g2core',
  label: 'g2core CNC',
  jobs: { start: 'g2core.run-job', pause: 'g2core.feedhold', resume: 'g2core.resume', stop: 'g2core.kill' },
  access: g2coreAccess,
  accessNeedsBody: g2coreAccessNeedsBody,
  accessBodyLimit: g2coreAccessBodyLimit,
  gateway: { sharing: g2coreSharing },
};
