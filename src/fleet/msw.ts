import { http, ws, HttpResponse, type RequestHandler, type WebSocketHandler } from 'msw';
import { SimDropped, type Simulator } from './sim';
import { apiOrigin, wsUrlFor } from './origin';

/**
 * msw handlers that let a simulator answer `/machines/<id>/...` in tests (component tests, Node
 * tests), exactly as the gateway would forward to a real controller. Tests only: the console
 * itself never runs msw (simulated machines are answered by the gateway).
 */
export function simulatorHandlers(
  machineId: string,
  sim: Simulator,
): Array<RequestHandler | WebSocketHandler> {
  const base = `${apiOrigin()}/machines/${machineId}`;
  const httpHandler = http.all(`${base}/*`, async ({ request }) => {
    const url = new URL(request.url);
    const prefix = `/machines/${machineId}`;
    const path = url.pathname.slice(prefix.length) + url.search;
    try {
      return await sim.fetch(request, path || '/');
    } catch (e) {
      if (e instanceof SimDropped) return HttpResponse.error();
      throw e;
    }
  });
  // Matches the machine's root socket too (`/machines/<id>/`, xTool) — a `/*` pattern does not.
  const escaped = wsUrlFor(base).replace(/[.*+?^${}()|[\]\\]/g, '\\$&');
  const link = ws.link(new RegExp(`^${escaped}(/.*)?$`));
  const wsHandler = link.addEventListener('connection', ({ client }) => {
    const url = new URL(client.url);
    let closed = false;
    client.addEventListener('close', () => {
      closed = true;
    });
    const path = url.pathname.slice(`/machines/${machineId}`.length) + url.search;
    const h = sim.socket?.(path || '/', {
      send: (d) => {
        if (!closed) client.send(d);
      },
      close: (code, reason) => {
        closed = true;
        client.close(code, reason);
      },
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
  return [httpHandler, wsHandler];
}
