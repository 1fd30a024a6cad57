import { ws, type RequestHandler, type WebSocketHandler } from 'msw';
import { simulatorHandlers } from '../../../fleet/msw';
import { apiOrigin, wsUrlFor } from '../../../fleet/origin';
import type { Simulator } from '../../../fleet/sim';

/**
 * msw handlers for a simulated xTool: the core's `simulatorHandlers` plus the socket at the
 * ROOT path `/machines/<id>/` — the xTool status socket is the root of the device's :8081, and
 * the core's `ws.link(`${base}/*`)` does not match an empty rest (checked with msw 2.15). Built
 * here until src/fleet/msw.ts matches `${base}/?$` as well; see the report.
 */
export function xtoolSimulatorHandlers(
  machineId: string,
  sim: Simulator,
): Array<RequestHandler | WebSocketHandler> {
  const base = wsUrlFor(`${apiOrigin()}/machines/${machineId}`);
  const root = new RegExp(`^${base.replace(/[.*+?^${}()|[\]\\]/g, '\\$&')}/?(\\?.*)?$`);
  const rootSocket = ws.link(root).addEventListener('connection', ({ client }) => {
    const url = new URL(client.url);
    const h = sim.socket?.(`/${url.search}`, {
      send: (d) => {
        try {
          client.send(d);
        } catch {
          /* the client went away */
        }
      },
      close: (code, reason) => client.close(code, reason),
    });
    if (!h) {
      client.close(4404, 'no socket here');
      return;
    }
    client.addEventListener('message', (ev) => {
      const d: unknown = ev.data;
      if (typeof d === 'string') h.message(d);
    });
    client.addEventListener('close', () => h.close());
  });
  return [rootSocket, ...simulatorHandlers(machineId, sim)];
}
