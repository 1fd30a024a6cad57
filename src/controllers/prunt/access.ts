import { defaultDecision, operator, read, supervisor, type AccessPolicy } from '../../fleet/access';

/**
 * Who may send which Prunt request (the gateway enforces it; the UI hides by the same rules).
 * - viewer: every GET (schemas, values, status, files, update check, board images) and the
 *   live socket (its only client→server frame is the tick divisor).
 * - operator: job controls — pause, resume, cancel, run an uploaded file (starting a print from
 *   the console is this printer's ordinary "start", not a remote-start safety override), uploading.
 * - supervisor: config writes, reloading the server, G-code console, firmware permission, deletes.
 * Anything undeclared: the core default (GET read, otherwise supervisor).
 */
export const pruntAccess: AccessPolicy = (req) => {
  const path = req.path.replace(/\/+$/, '') || '/';
  if (req.websocket) return read('live status and logs');
  const m = req.method.toUpperCase();
  if (m === 'GET' || m === 'HEAD') {
    // GET /config/values only reads (prunt-config.adb `Get_Values`): Prunt writes its config file
    // once at its first access after a start and on a save (POST), never on a read. Not audited.
    return read();
  }
  if (m === 'POST') {
    switch (path) {
      case '/pause/pause':
        return operator('pause', 'prunt.pause');
      case '/pause/resume':
        return operator('resume', 'prunt.resume');
      case '/cancel':
        return operator('cancel the running file', 'prunt.cancel');
      case '/run-file':
        return operator('run a file', 'prunt.runFile');
      case '/run-command':
        return supervisor('run a G-code command');
      case '/config/values':
        return supervisor('change the configuration');
      case '/reload-server':
        return supervisor('reload the server');
      case '/allow-firmware-update':
        return supervisor('allow a firmware update');
    }
  }
  if (m === 'PUT' && path.startsWith('/uploads/')) return operator('upload a file');
  if (m === 'DELETE' && path.startsWith('/uploads/')) return supervisor('delete a file');
  return defaultDecision(req);
};
