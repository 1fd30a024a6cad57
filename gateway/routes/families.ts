import type { ConfigService } from '../services';
import { sendJson } from '../http-util';
import type { ApiRoute } from './route';

/** A family's route name and kind as they may appear in a path. */
const SEGMENT = /^[a-z0-9-]{1,40}$/;

/**
 * A family's own routes (its server part's `routes`, e.g. xTool discovery): `GET /api/<name>/<kind>`,
 * the role and the 403 message each declares. Listed after the gateway's own routes.
 */
export function familyRoutes({ opts, env }: Pick<ConfigService, 'opts' | 'env'>): ApiRoute[] {
  const routes: ApiRoute[] = [];
  const kinds = new Set<string>();
  for (const f of Object.values(opts.families)) {
    // The first family of a kind answers (as the lookup by kind did).
    if (!f || kinds.has(f.kind)) continue;
    kinds.add(f.kind);
    const names = new Set<string>();
    for (const r of f.server?.routes ?? []) {
      if (!SEGMENT.test(r.name) || !SEGMENT.test(f.kind) || names.has(r.name)) continue;
      names.add(r.name);
      routes.push({
        method: 'GET',
        path: `/api/${r.name}/${f.kind}`,
        role: r.role,
        refusal: r.forbidden,
        changesState: false,
        audited: false,
        async handle(req, res) {
          const answer = await r.handle({ env, discovery: opts.discovery ?? {} });
          sendJson(res, answer.status, answer.body);
        },
      });
    }
  }
  return routes;
}
