import type { FamilyDeclaration, GatewayHints } from '../../fleet/contract';
import { takesApiKey, touchcutAccess } from './access';
import { touchcutHeldSession } from './gateway';
import { touchcutSharing } from './sharing';
import { touchcutManifest } from './manifest';

/**
 * Node-safe declaration of the Kinetic TouchCut family (no React, no views, no CSS, no simulator:
 * the gateway and the browser import it).
 *
 * Gateway notes for the lead:
 * - TouchCut serves HTTPS with its own self-signed certificate: the gateway pins it per machine
 *   (gateway/tls-pin.ts: `tlsFingerprint`, or trust on first use), never accepts any certificate.
 * - The machine's `url` is the host; the client's paths already start with `/rest/v1/`.
 * - The gateway holds the TouchCut user login (`session`, gateway.ts): the JWT never reaches a
 *   browser; without one, `injectSecrets` adds the API key.
 */
export const touchcutGateway: GatewayHints = {
  /**
   * Adds `X-TouchCut-API-Key` from the machine's apiKey to GET requests of the documented reads
   * that take it (status, stats, monitor, programs, unloader, screenshot: `takesApiKey`, the same
   * path form the access rule uses), and to nothing else: no other method, no undocumented path, not
   * machine-info or auth (they take no key). Not when the request carries the gateway's held JWT
   * (`Authorization: Bearer`, added by the held session before this runs: a TouchCut user login;
   * the manual says the JWT takes precedence, and the user's own privileges are what they logged
   * in for). Whatever `Authorization` a browser sent was dropped before (gateway.ts `apply`). The
   * key goes in a header only, never the query (queries end up in logs and error echoes). A key
   * the browser tried to send itself is always dropped: the browser never holds one.
   */
  injectSecrets(req, secrets) {
    for (const k of Object.keys(req.headers))
      if (k.toLowerCase() === 'x-touchcut-api-key') delete req.headers[k];
    const bearer = Object.entries(req.headers).some(
      ([k, v]) => k.toLowerCase() === 'authorization' && /^bearer\s+\S/i.test(v),
    );
    if (secrets.apiKey && !bearer && takesApiKey(req.method, req.path))
      req.headers['X-TouchCut-API-Key'] = secrets.apiKey;
  },
  session: touchcutHeldSession,
  /** One upstream per machine for every viewer: the polled reads, the watch (`sharing.ts`). */
  sharing: touchcutSharing,
};

export const touchcutDeclaration: FamilyDeclaration = {
  kind: touchcutManifest.kind,
  label: touchcutManifest.label,
  access: touchcutAccess,
  gateway: touchcutGateway,
};
