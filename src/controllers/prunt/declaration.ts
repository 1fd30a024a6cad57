import type { FamilyDeclaration } from '../../fleet/contract';
import { pruntAccess } from './access';
import { pruntSharing } from './sharing';
import { pruntManifest } from './manifest';

/**
 * Node-safe declaration of the Prunt family (no React, no views, no CSS, no simulator): the
 * gateway and the browser import it.
 */
export const pruntDeclaration: FamilyDeclaration = {
  kind: pruntManifest.kind,
  label: pruntManifest.label,
  jobs: pruntManifest.jobs,
  access: pruntAccess,
  gateway: {
    // Pictures in the schema's help texts (`<image src="extras/images/stepper_1.png">`).
    imageAnswer: (path) => /^\/extras\/images\/[^/]+\.(png|jpe?g|gif|webp)$/i.test(path),
    // One upstream per machine for every viewer: `/websocket/everything` and the watch.
    sharing: pruntSharing,
  },
};
