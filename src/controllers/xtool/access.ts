import {
  operator,
  read,
  supervisor,
  type AccessDecision,
  type AccessPolicy,
  type AccessRequest,
} from '../../fleet/access';

/**
 * Who may send which request to an xTool D-series laser. The gateway enforces this on every
 * proxied request; the session's command declarations use the same roles.
 *
 * The firmware performs actions on plain GETs (/cnc/data?action=, /system?action=set*, /cmd,
 * /read, /delete): those are declared `command: true` so the gateway audits them. A GET the
 * document does not list may do anything on this firmware (e.g. /framing, "usage unknown"), so
 * unknown GETs are supervisor-only commands here, stricter than the core default.
 */

/** /system actions that only read. */
const SYSTEM_READS = new Set(['mac', 'version', 'get_working_sta', 'offset', 'dotMode', 'get_dev_name']);

const SYSTEM_LABELS: Record<string, string> = {
  set_dev_name: 'rename the laser',
  setLimitStopSwitch: 'switch the limit stop',
  setTiltStopSwitch: 'switch the tilt stop',
  setMovingStopSwitch: 'switch the movement stop',
  setTiltCheckThreshold: 'set the tilt threshold',
  setMovingCheckThreshold: 'set the movement threshold',
  setFlameAlarmMode: 'set the flame alarm mode',
  setFlameAlarmSensitivity: 'set the flame alarm sensitivity',
};

const JOB_ACTIONS: Record<string, string> = {
  pause: 'pause the job',
  resume: 'resume the job',
  stop: 'stop the job',
};

/** Plain reads, GET only. `/status` is probed to recognize other xTool models. */
const READS = new Set([
  '/',
  '/ping',
  '/progress',
  '/getmachinetype',
  '/getlaserpowertype',
  '/getlaserpowerinfo',
  '/peripherystatus',
  '/list',
  '/status',
]);

function normalize(path: string): string {
  const p = path.split('?')[0] ?? '/';
  return p.length > 1 ? p.replace(/\/+$/, '') : p;
}

export const xtoolAccess: AccessPolicy = (req: AccessRequest): AccessDecision => {
  if (req.websocket) return read('live status frames');
  const path = normalize(req.path);
  const method = req.method.toUpperCase();
  const isGet = method === 'GET' || method === 'HEAD';

  if (isGet && READS.has(path)) return read();

  if (path === '/system' && isGet) {
    const action = req.query.get('action') ?? '';
    if (SYSTEM_READS.has(action)) return read('read settings');
    return supervisor(
      SYSTEM_LABELS[action] ?? `system action "${action}" (not in the document: supervisor only)`,
    );
  }

  if (path === '/cnc/data') {
    if (isGet) {
      const action = req.query.get('action') ?? '';
      const label = Object.hasOwn(JOB_ACTIONS, action) ? JOB_ACTIONS[action] : undefined;
      return label
        ? operator(label, `xtool.${action}`)
        : supervisor(`job action "${action}" (unknown: supervisor only)`);
    }
    // POST /cnc/data is the same upload as POST /upload (document).
    if (method === 'POST') return operator('upload a job file');
  }

  if (path === '/upload' && method === 'POST') return operator('upload a job file');
  if (path === '/cmd') return supervisor('send G-code');
  if (path === '/read' && isGet)
    return { ...supervisor('run a file from the SD card (fires the laser)'), id: 'xtool.run-file' };
  if (path === '/delete' && isGet) return supervisor('delete a file from the SD card');
  if (path === '/upgrade' && method === 'POST') return supervisor('upload firmware');
  if (path === '/updater' && isGet)
    return { role: 'supervisor', command: false, label: 'open the firmware updater' };
  if (path === '/net') return supervisor('change the WiFi settings');

  return supervisor(`${method} ${path} (not in the document: supervisor only)`);
};
