import {
  defaultDecision,
  operator,
  read,
  type AccessDecision,
  type AccessPolicy,
  type AccessRequest,
} from '../../fleet/access';

/**
 * Who may send which TouchCut request (enforced by the gateway, mirrored by the UI).
 *
 * The TouchCut REST API v1 is read-only apart from its two auth requests, so:
 * - every documented GET is a viewer read (status, stats, monitor, programs, unloader, screenshot,
 *   machine-info);
 * - `POST auth` (a TouchCut user login) is allowed to viewers and not a command: it changes nothing
 *   on the machine, and TouchCut's own user privileges then govern what the token may read;
 * - `POST auth/change-password` changes a TouchCut account: operator and audited (the TouchCut user
 *   changes their own password, knowing the old one);
 * - anything else (undocumented methods/paths) falls to the core default: GET is a read, any other
 *   method supervisor-only;
 * - no GET is a command: none of them changes the machine.
 */

function normalize(path: string): string {
  const p = path.split('?')[0] ?? '';
  return ('/' + p.replace(/^\/+/, '')).replace(/\/+$/, '').toLowerCase();
}

export const touchcutAccess: AccessPolicy = (req: AccessRequest): AccessDecision => {
  const path = normalize(req.path);
  const m = /^\/rest\/v1\/(.+)$/.exec(path);
  if (!m || req.websocket) return defaultDecision(req);
  const resource = m[1];
  if (req.method === 'GET' || req.method === 'HEAD') {
    switch (resource) {
      case 'machine-info':
        return read('read machine information');
      case 'status':
        return read('read status');
      case 'stats':
        return read('read production statistics');
      case 'monitor':
        return read('monitor axes and I/O');
      case 'programs':
        return read('read programs');
      case 'unloader':
        return read('read the part unloader');
      case 'screenshot':
        return read('view the TouchCut screen');
      default:
        return defaultDecision(req);
    }
  }
  if (req.method === 'POST' && resource === 'auth') {
    return { role: 'viewer', command: false, label: 'log in as a TouchCut user' };
  }
  if (req.method === 'POST' && resource === 'auth/change-password') {
    return operator('change the TouchCut user password');
  }
  return defaultDecision(req);
};
