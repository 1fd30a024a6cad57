import { splitPath, type Simulator } from '../../fleet/sim';
import { touchcutGateway } from './declaration';

/**
 * Test helper (not used by the app): a stand-in for the console's gateway in front of a
 * simulator, applying the family's own `injectSecrets` exactly as the real gateway must. It
 * records what the browser sent before the gateway touched it.
 */
export interface GatewayStandIn extends Simulator {
  /** Requests as the browser sent them (headers lower-cased). */
  fromBrowser: Array<{ method: string; path: string; headers: Record<string, string> }>;
  apiKey: string | undefined;
}

export function viaGateway(sim: Simulator, apiKey?: string): GatewayStandIn {
  const g: GatewayStandIn = {
    kind: sim.kind,
    apiKey,
    fromBrowser: [],
    async fetch(req, path) {
      const headers: Record<string, string> = {};
      req.headers.forEach((v, k) => (headers[k] = v));
      g.fromBrowser.push({ method: req.method, path, headers: { ...headers } });
      const { pathname, query } = splitPath(path);
      touchcutGateway.injectSecrets?.(
        { method: req.method, path: pathname, headers, query },
        { apiKey: g.apiKey },
      );
      const body = req.method === 'GET' || req.method === 'HEAD' ? undefined : await req.text();
      const qs = query.toString();
      const fwd = new Request(req.url, { method: req.method, headers, body });
      return sim.fetch(fwd, pathname + (qs ? `?${qs}` : ''));
    },
    controls: () => sim.controls?.() ?? [],
    dispose: () => sim.dispose(),
  };
  return g;
}
