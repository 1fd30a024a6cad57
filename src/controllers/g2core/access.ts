import {
  defaultDecision,
  operator,
  read,
  supervisor,
  type AccessDecision,
  type AccessPolicy,
  type BodyNeeded,
} from '../../fleet/access';

/**
 * Who may send which g2core REST request (enforced by the gateway, mirrored by the UI).
 *
 *  viewer      every GET that only reads (version, status reports, machine tree, operations, jobs)
 *  operator    job controls: pause / resume / kill operations and jobs, queue and start jobs,
 *              upload job files; alarm clear (`GET /machine/clear`, a GET that is a command);
 *              jog and home (POST /operation whose lines are all jog or G28.2 lines, see
 *              `isJogOrHomeLine`: operators stand at the machine); feed/spindle overrides
 *              (`PUT /machine/mfo|mto|sso`)
 *  supervisor  settings (`PUT /machine/…`), the G-code console (any other POST /operation),
 *              triggering alarm/shutdown/panic (`GET /machine/alarm|shutd|panic`), deleting jobs,
 *              anything undeclared that is not a GET.
 *
 * POST /operation is classified by its body: `accessNeedsBody` asks the gateway to read it.
 */

/** Override keys an operator may set while a job runs (sys group). */
export const OVERRIDE_KEYS = ['mfo', 'mto', 'sso'] as const;

const AXIS_WORD = '[XYZABC][-+]?(?:\\d+\\.?\\d*|\\.\\d+)';
const NUM = '(?:\\d+\\.?\\d*|\\.\\d+)';
const JOG_LINE = new RegExp(`^G91\\s*G[01](?:\\s*${AXIS_WORD})+(?:\\s*F${NUM})?$`, 'i');
const HOME_LINE = new RegExp(`^G28\\.2(?:\\s*[XYZABC]0)+$`, 'i');
const RESTORE_LINE = /^G90$/i;

/** True for the only lines an operator's operation may contain: relative jogs, G90, G28.2 homing. */
export function isJogOrHomeLine(line: string): boolean {
  const l = line.trim();
  return JOG_LINE.test(l) || HOME_LINE.test(l) || RESTORE_LINE.test(l);
}

function operationDecision(body: string | undefined): AccessDecision {
  const console = supervisor('run G-code (console)');
  if (!body) return console;
  let parsed: unknown;
  try {
    parsed = JSON.parse(body);
  } catch {
    return console;
  }
  if (typeof parsed !== 'object' || parsed === null) return console;
  const { optype, value } = parsed as { optype?: unknown; value?: unknown };
  if (optype === 'sendfile') return operator('run a job file');
  if (optype !== 'run') return console;
  const lines = Array.isArray(value)
    ? value
    : typeof value === 'string'
      ? value.split(/\r?\n/).filter((l) => l.trim() !== '')
      : null;
  if (!lines || lines.length === 0 || !lines.every((l) => typeof l === 'string' && isJogOrHomeLine(l)))
    return console;
  return (lines as string[]).some((l) => /G28\.2/i.test(l)) ? operator('home axes') : operator('jog');
}

export const g2coreAccess: AccessPolicy = (req) => {
  const path = req.path.replace(/\/+$/, '') || '/';
  const m = req.method.toUpperCase();
  if (req.websocket) return defaultDecision(req);

  if (m === 'GET' || m === 'HEAD') {
    const key = /^\/machine\/([^/]+)$/.exec(path)?.[1]?.toLowerCase();
    if (key === 'clear' || key === 'clr') return operator('clear alarm');
    if (key === 'alarm' || key === 'shutd' || key === 'panic') return supervisor(`trigger ${key}`);
    return read();
  }

  if (m === 'PUT' && path.startsWith('/machine/')) {
    const rest = path.slice('/machine/'.length).replace(/^sys[/.]/, '');
    if ((OVERRIDE_KEYS as readonly string[]).includes(rest)) return operator('change feed/spindle override');
    return supervisor('change a setting');
  }
  if (m === 'POST' && path === '/operation') return operationDecision(req.body);
  if (m === 'PUT' && /^\/operation\/[^/]+$/.test(path)) return operator('pause, resume or kill an operation');
  if (m === 'POST' && path === '/job') return operator('queue a job (upload)');
  if (m === 'PUT' && /^\/job\/[^/]+$/.test(path)) return operator('start, pause, kill or reorder a job');
  if (m === 'DELETE' && /^\/job\/[^/]+$/.test(path)) return supervisor('delete a job');
  return defaultDecision(req);
};

export const g2coreAccessNeedsBody: BodyNeeded = (method, path) =>
  method.toUpperCase() === 'POST' && path.replace(/\/+$/, '') === '/operation';
