import type { FamilyDeclaration } from '../../fleet/contract';
import { xtoolAccess } from './access';
import { xtoolSharing } from './sharing';
import { xtoolManifest } from './manifest';

/**
 * The Node-safe declaration of the xTool D-series family: access rules, gateway hints. No React,
 * views, CSS or simulator here: the gateway and the browser import this file.
 */
export const xtoolDeclaration: FamilyDeclaration = {
  kind: xtoolManifest.kind,
  label: xtoolManifest.label,
  jobs: xtoolManifest.jobs,
  access: xtoolAccess,
  gateway: {
    // The status WebSocket is on :8081 of the same host (document, "TCP Ports"); the client
    // opens `/machines/<id>/`, i.e. the root path of the device's :8081.
    defaultWsPort: 8081,
    // One upstream per laser for every viewer: the status poll, the :8081 socket, the watch.
    sharing: xtoolSharing,
  },
};
