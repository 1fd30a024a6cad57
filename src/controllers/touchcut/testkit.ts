import type { UpstreamAnswer, UpstreamRequest } from '../../fleet/contract';
import { splitPath, type Simulator } from '../../fleet/sim';
import { touchcutGateway } from './declaration';
import { touchcutHeldSession } from './gateway';

/**
 * Test helper (not used by the app): a stand-in for the console's gateway in front of a
 * simulator, applying the family's own hooks exactly as the real gateway does
 * (gateway/held-session.ts, gateway/proxy-http.ts): the held TouchCut login (`session`: login,
 * login state, logout and password change answered or sent by the gateway, the JWT kept here and
 * added to every request, dropped on a 401) and `injectSecrets` (the API key). It records what the
 * browser sent before the gateway touched it, and what it answered.
 */
export interface GatewayStandIn extends Simulator {
  /** Requests as the browser sent them (headers lower-cased). */
  fromBrowser: Array<{ method: string; path: string; headers: Record<string, string> }>;
  /** Bodies of the answers the browser got from the stand-in itself (login, state, password change). */
  toBrowser: string[];
  apiKey: string | undefined;
  /** The JWT the stand-in holds for the machine, or null. */
  readonly heldToken: string | null;
}

function toResponse(a: UpstreamAnswer): Response {
  const body = a.status === 204 || a.status === 304 || a.body === '' ? null : a.body;
  return new Response(body, { status: a.status, headers: a.headers });
}

async function toAnswer(r: Response): Promise<UpstreamAnswer> {
  const headers: Record<string, string> = {};
  r.headers.forEach((v, k) => (headers[k.toLowerCase()] = v));
  return { status: r.status, headers, body: await r.text() };
}

export function viaGateway(sim: Simulator, apiKey?: string): GatewayStandIn {
  const hooks = touchcutHeldSession;
  let key: string | null = null;
  let answer: UpstreamAnswer | null = null;
  const upstream: UpstreamRequest = async (method, pq, headers = {}, body) =>
    toAnswer(await sim.fetch(new Request(`http://sim${pq}`, { method, headers, body }), pq));
  const own = (a: UpstreamAnswer): Response => {
    g.toBrowser.push(a.body);
    return toResponse(a);
  };
  const g: GatewayStandIn = {
    kind: sim.kind,
    apiKey,
    fromBrowser: [],
    toBrowser: [],
    get heldToken() {
      return key;
    },
    async fetch(req, path) {
      const headers: Record<string, string> = {};
      req.headers.forEach((v, k) => (headers[k] = v));
      g.fromBrowser.push({ method: req.method, path, headers: { ...headers } });
      const { pathname, query } = splitPath(path);
      const method = req.method.toUpperCase();
      const body = method === 'GET' || method === 'HEAD' ? undefined : await req.text();
      const i = hooks.intercept({ method, path: pathname, query });
      if (i?.kind === 'answer') return own(i.answer);
      if (i?.kind === 'close') {
        if (i.end) {
          key = null;
          answer = null;
        }
        return new Response(null, { status: 204 });
      }
      if (i?.kind === 'open') {
        const typed = i.fromBody ? i.fromBody(body ?? '', headers['content-type'] ?? '') : i.credentials;
        if (typed === undefined && answer) return own(answer);
        const o = await hooks.open(upstream, typed);
        if (!o.ok) return own(o.answer);
        key = o.key;
        answer = o.answer;
        return own(o.answer);
      }
      hooks.apply({ headers, query }, key);
      touchcutGateway.injectSecrets?.({ method, path: pathname, headers, query }, { apiKey: g.apiKey });
      const qs = query.toString();
      const pq = pathname + (qs ? `?${qs}` : '');
      const used = key;
      if (i?.kind === 'exchange') {
        const a = await upstream(method, pq, headers, body);
        const x = hooks.exchanged?.(a, answer) ?? { key: null, answer: a };
        if (x.key !== null && key === used) {
          key = x.key;
          answer = x.answer;
        }
        return own(x.answer);
      }
      const res = await sim.fetch(new Request(req.url, { method, headers, body }), pq);
      if (hooks.isExpired(res.status, { method, path: pathname }) && used !== null && key === used) {
        key = null;
        answer = null;
      }
      return res;
    },
    controls: () => sim.controls?.() ?? [],
    dispose: () => sim.dispose(),
  };
  return g;
}
