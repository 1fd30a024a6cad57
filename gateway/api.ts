import { createAlarmStores, type AlarmCentre } from './alarms';
import type { GatewayContext } from './context';
import type { History } from './history';
import { alarmsRoutes } from './routes/alarms';
import { auditRoutes } from './routes/audit';
import { familyRoutes } from './routes/families';
import { historyRoutes } from './routes/history';
import { machinesRoutes, type Watched } from './routes/machines';
import { fastifyApi } from './routes/fastify-api';
import type { ApiRoute } from './routes/route';
import { sessionRoutes } from './routes/session';
import { settingsRoutes } from './routes/settings';
import { tlsRoutes } from './routes/tls';
import type { SettingsStore } from './settings';
import { TemperatureStore } from './temperatures';
import type { Webhook } from './webhook';

/**
 * `/api/*`: the table of declared routes (routes/, one module per area), answered by Fastify
 * (routes/fastify-api.ts): match, method, the role a route declares (a hook), then its handler.
 * Cross-site requests and unknown hosts were refused before this (gateway.ts, csrf.ts).
 */

export { watchForPage, type Watched } from './routes/machines';

/** The gateway's own stores the API answers from besides the context (gateway.ts makes them). */
export interface ApiStores {
  alarms: AlarmCentre;
  settings: SettingsStore;
  webhook: Webhook;
  /** The production history (`/api/history/*`); absent: those routes answer 404. */
  history?: History;
  /** What the gateway's watch knows of a machine now (watch.ts); absent: nothing is watched. */
  watched?: (id: string) => Watched | null;
  /** Asks the watch of a machine to read it now (watch.ts `lookNow`); absent: nothing is watched. */
  lookNow?: (id: string) => void;
  /** The last minutes of temperatures (temperatures.ts); absent: every machine has none. */
  temperatures?: TemperatureStore;
}

/** The `/api/*` routes in the order the table tries them (the gateway's own, then the families'). */
export function apiRoutes(ctx: GatewayContext, stores: ApiStores): ApiRoute[] {
  const { alarms, settings, webhook, history } = stores;
  return [
    ...sessionRoutes(ctx),
    ...machinesRoutes({
      ...ctx,
      watched: stores.watched,
      lookNow: stores.lookNow,
      temperatures: stores.temperatures ?? new TemperatureStore(ctx.now, ctx.scrub),
    }),
    ...auditRoutes(ctx),
    ...alarmsRoutes({ ...ctx, alarms }),
    ...settingsRoutes({ ...ctx, settings, webhook, history }),
    ...tlsRoutes(ctx),
    ...historyRoutes(ctx, history),
    ...familyRoutes(ctx),
  ];
}

export function createApi(ctx: GatewayContext, stores: ApiStores = createAlarmStores(ctx)) {
  const routes = apiRoutes(ctx, stores);
  return Object.assign(fastifyApi(routes, ctx), { routes: routes as readonly ApiRoute[] });
}
