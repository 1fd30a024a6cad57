import type { FamilyDeclaration } from '../../fleet/contract';
import { g2coreAccess, g2coreAccessBodyLimit, g2coreAccessNeedsBody } from './access';
import { g2coreSharing } from './sharing';
import { g2coreManifest } from './manifest';

/**
 * The Node-safe declaration of the g2core family: access rules. No React, views, CSS or simulator
 * here: the gateway and the browser import this file. The REST design has no secrets and no
 * WebSocket: the only gateway hint is how the controller is shared (`sharing.ts`).
 */
export const g2coreDeclaration: FamilyDeclaration = {
  kind: g2coreManifest.kind,
  label: g2coreManifest.label,
  jobs: g2coreManifest.jobs,
  access: g2coreAccess,
  accessNeedsBody: g2coreAccessNeedsBody,
  accessBodyLimit: g2coreAccessBodyLimit,
  gateway: { sharing: g2coreSharing },
};
