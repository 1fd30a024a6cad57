import {
  operator,
  read,
  supervisor,
  type AccessDecision,
  type AccessPolicy,
  type AccessRequest,
} from '../../fleet/access';

/**
 * Who may send which TouchCut request (enforced by the gateway, mirrored by the UI).
 *
 * The TouchCut REST API v1 is read-only apart from its two auth requests, so:
 * - every documented GET (and HEAD) is a viewer read: status, stats, monitor, programs, unloader,
 *   screenshot, machine-info;
 * - `GET auth` (answered by the gateway, gateway.ts): which TouchCut user the console is logged in
 *   as, a viewer read;
 * - `POST auth` (log in) and `DELETE auth` (log out, answered by the gateway) need an operator and
 *   are audited commands. The gateway holds the login for the machine, shared by every viewer: it
 *   decides whose TouchCut privileges everybody reads with and whether the password change is
 *   possible, so a viewer may not switch it (a viewer logging out would leave a machine without
 *   an API key dark for everyone). The operator is the person at the machine, who can log in at
 *   TouchCut's own screen anyway, and must be able to log in again when a login expires;
 *   requiring a supervisor would leave the tablet at the machine stuck. The password is in the
 *   body, never in the audit log;
 * - `POST auth/change-password` changes a TouchCut account: operator and audited (the TouchCut user
 *   changes their own password, knowing the old one);
 * - anything else needs a supervisor, GETs included: TouchCut's web server has more than the
 *   documented API (its web interface can move the part unloader), and a GET there may act;
 * - WebSocket upgrades need a supervisor: the API has none, and TouchCut would see a GET.
 *
 * Paths are compared in one form (`touchcutResource`: case-insensitive, trailing and repeated
 * slashes ignored); the gateway's `injectSecrets` (family.ts) uses the same form (`takesApiKey`)
 * to add the API key to the documented reads only.
 */

/** Documented reads that take the API key (machine-info needs no login, auth takes no key). */
export const KEYED_READS = ['status', 'stats', 'monitor', 'programs', 'unloader', 'screenshot'] as const;

const READ_LABELS: Record<string, string> = {
  'machine-info': 'read machine information',
  status: 'read status',
  stats: 'read production statistics',
  monitor: 'monitor axes and I/O',
  programs: 'read programs',
  unloader: 'read the part unloader',
  screenshot: 'view the TouchCut screen',
};

/**
 * The resource under `/rest/v1/` a path names, lower-cased, empty and trailing segments ignored
 * (`/REST//v1/Status/` → "status", `/rest/v1/auth/change-password` → "auth/change-password").
 * Null for a path outside `/rest/v1/`. Percent-encoded characters stay encoded, so `status%2F..`
 * is not "status".
 */
export function touchcutResource(path: string): string | null {
  const segs = (path.split('?')[0] ?? '')
    .split('/')
    .filter((s) => s !== '')
    .map((s) => s.toLowerCase());
  if (segs.length < 3 || segs[0] !== 'rest' || segs[1] !== 'v1') return null;
  return segs.slice(2).join('/');
}

/** Whether the gateway adds the API key: GETs of the documented key-taking reads, nothing else. */
export function takesApiKey(method: string, path: string): boolean {
  if (method.toUpperCase() !== 'GET') return false;
  const r = touchcutResource(path);
  return r !== null && (KEYED_READS as readonly string[]).includes(r);
}

export const touchcutAccess: AccessPolicy = (req: AccessRequest): AccessDecision => {
  const method = req.method.toUpperCase();
  if (req.websocket) return supervisor('open a WebSocket (TouchCut has none: it would see a GET)');
  const resource = touchcutResource(req.path);
  if (resource !== null && (method === 'GET' || method === 'HEAD')) {
    // Own keys only: `constructor` or `__proto__` is not a documented read.
    const label = Object.hasOwn(READ_LABELS, resource) ? READ_LABELS[resource] : undefined;
    if (label) return read(label);
  }
  if (resource === 'auth') {
    if (method === 'GET' || method === 'HEAD')
      return read('see which TouchCut user the console is logged in as');
    if (method === 'POST') return operator('log the machine in to TouchCut as a user (for every viewer)');
    if (method === 'DELETE') return operator('log the machine out of TouchCut (for every viewer)');
  }
  if (method === 'POST' && resource === 'auth/change-password') {
    return operator('change the TouchCut user password');
  }
  return supervisor(`${method} ${req.path} (not a documented TouchCut request: supervisor only)`);
};
