import type { FamilyDeclaration } from '../../fleet/contract';
import { duetAccess, duetAccessNeedsBody } from './access';
import { duetHeldSession } from './gateway';
import { duetSharing } from './sharing';
import { duetManifest } from './manifest';

/**
 * Node-safe declaration of the Duet (DSF) family: access rules and gateway hints. No React,
 * views, CSS or simulator here — the gateway and the browser import it.
 */
export const duetDeclaration: FamilyDeclaration = {
  kind: duetManifest.kind,
  label: duetManifest.label,
  jobs: duetManifest.jobs,
  access: duetAccess,
  accessNeedsBody: duetAccessNeedsBody,
  gateway: {
    /**
     * The gateway holds the DSF session (`gateway.ts`): it connects with the machine's password
     * (or one a user typed into the login form) and keeps the key; browsers never get it.
     */
    session: duetHeldSession,
    /** One upstream per machine for every viewer: shared reads, `WS /machine`, the watch (`sharing.ts`). */
    sharing: duetSharing,
  },
};
