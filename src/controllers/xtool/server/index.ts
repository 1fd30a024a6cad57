import type { FamilyServerPart } from '../../../fleet/server-part';
import { discoverXtool } from './discovery';

/**
 * The xTool family's server part (Node-only; the page never imports it): finding lasers on the
 * network (`GET /api/discover/xtool`, supervisors), by the protocol's UDP/TCP discovery.
 */

function envNumber(env: NodeJS.ProcessEnv, key: string): number | undefined {
  const v = env[key];
  if (!v) return undefined;
  const n = Number(v);
  return Number.isFinite(n) && n > 0 ? n : undefined;
}

export const xtoolServer: FamilyServerPart = {
  routes: [
    {
      name: 'discover',
      role: 'supervisor',
      forbidden: 'finding lasers on the network is for supervisors',
      handle: async ({ env, discovery: d }) => ({
        status: 200,
        body: await discoverXtool({
          broadcast: d.broadcast ?? env.SHOPDECK_DISCOVERY_BROADCAST ?? '255.255.255.255',
          udpPort: d.udpPort ?? envNumber(env, 'SHOPDECK_DISCOVERY_UDP_PORT') ?? 20000,
          tcpPort: d.tcpPort ?? envNumber(env, 'SHOPDECK_DISCOVERY_TCP_PORT') ?? 20001,
          listenUdpPort: d.listenUdpPort,
          listenMs: d.listenMs ?? 2000,
          bindAddress: d.bindAddress,
        }),
      }),
    },
  ],
};
