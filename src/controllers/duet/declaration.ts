import type { FamilyDeclaration } from '../../fleet/contract';
import { duetAccess, duetAccessNeedsBody } from './access';
import { duetHeldSession, duetHeldSessionFor, type DuetApiState } from './gateway';
import { duetSharing, duetSharingFor } from './sharing';

/**
 * Node-safe declaration of the Duet (DSF) family: access rules and gateway hints. No React,
 * views, CSS or simulator here — the gateway and the browser import it.
 */
export const duetDeclaration: FamilyDeclaration = {
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
    /** One upstream per machine for every viewer: shared reads, `WS /machine`, the watch (`sharing.ts`). */
    sharing: duetSharing,
    /**
     * Per machine: DSF or standalone (`rr_*`), learned by the held session's probe (or the
     * machines file's `api`) and then followed by the sharing (limits, watch). Built on `this`,
     * so a declaration that replaces `session` or `sharing` keeps its replacements.
     */
    forMachine(m) {
      const state: DuetApiState = { api: m.api ?? null };
      return {
        session: duetHeldSessionFor(state, this.session),
        sharing: duetSharingFor(state, this.sharing),
      };
    },
  },
};
