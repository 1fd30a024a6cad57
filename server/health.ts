import type { IncomingMessage, ServerResponse } from 'node:http';
import type { MachinesConfig } from '../gateway/machines';
import { readUsers } from '../gateway/users';
import { isLoopback } from './hosts';

/** `/healthz`: whether the machines and users files loaded (503 when not, or while stopping). */

export interface HealthReport {
  ok: boolean;
  machines: { loaded: boolean; file: string | null; demo: boolean; count: number };
  users:
    | { mode: 'open'; file: string }
    | { mode: 'secured'; loaded: true; file: string; count: number }
    | { mode: 'secured'; loaded: false; file: string; error: string };
  https: boolean;
  stopping: boolean;
  /** Seconds since the server started. */
  uptime: number;
}

/** The server's health now; the server started when this is made. */
export function createHealth(o: {
  usersFile: string;
  machines: MachinesConfig;
  /** The users file was there at start (the console was secured). */
  securedAtStart: boolean;
  https: () => boolean;
  stopping: () => boolean;
}): () => HealthReport {
  const { usersFile, machines } = o;
  let securedOnce = o.securedAtStart;
  const startedAt = Date.now();
  return () => {
    let users: HealthReport['users'];
    try {
      const list = readUsers(usersFile);
      if (list) {
        securedOnce = true;
        users = { mode: 'secured', loaded: true, file: usersFile, count: list.length };
      } else if (securedOnce) {
        // The gateway stays secured (nobody can log in) until the file is back: users.ts.
        users = {
          mode: 'secured',
          loaded: false,
          file: usersFile,
          error: 'the users file is gone: nobody can log in',
        };
      } else {
        users = { mode: 'open', file: usersFile };
      }
    } catch (e) {
      users = {
        mode: 'secured',
        loaded: false,
        file: usersFile,
        error: e instanceof Error ? e.message : String(e),
      };
    }
    const stopping = o.stopping();
    const ok = !stopping && (users.mode === 'open' || users.loaded);
    return {
      ok,
      machines: {
        loaded: true,
        file: machines.file,
        demo: machines.file === null,
        count: machines.machines.length,
      },
      users,
      https: o.https(),
      stopping,
      uptime: Math.round((Date.now() - startedAt) / 1000),
    };
  };
}

/** /healthz for the network: healthy or not, and why in one word each, without paths or counts. */
function publicHealth(h: HealthReport): Record<string, unknown> {
  return {
    ok: h.ok,
    machines: { loaded: h.machines.loaded },
    users: { mode: h.users.mode, loaded: h.users.mode === 'open' || h.users.loaded },
    https: h.https,
    stopping: h.stopping,
  };
}

/** `GET|HEAD /healthz`: 200 or 503 with the report. */
export function answerHealth(
  req: IncomingMessage,
  res: ServerResponse,
  method: string,
  h: HealthReport,
): void {
  // File paths, user counts and error words are for this computer (a health check, an
  // admin); anyone else on the network learns only whether the console is healthy.
  const body = JSON.stringify(isLoopback(req.socket.remoteAddress) ? h : publicHealth(h));
  res.writeHead(h.ok ? 200 : 503, {
    'Content-Type': 'application/json; charset=utf-8',
    'Content-Length': Buffer.byteLength(body),
    'Cache-Control': 'no-store',
  });
  res.end(method === 'HEAD' ? undefined : body);
}
