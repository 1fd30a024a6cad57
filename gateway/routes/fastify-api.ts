import type { IncomingMessage, ServerResponse } from 'node:http';
import Fastify, { type FastifyReply, type FastifyRequest } from 'fastify';
import {
  answerUnrouted,
  DEFAULT_BODY_LIMIT,
  guardRoute,
  resolveRoute,
  routeCall,
  routeKey,
  runRoute,
  type ApiRoute,
  type Guard,
  type GuardedCall,
  type RouteCall,
} from './route';

/**
 * `/api/*` on Fastify: each declared route (route.ts) is a Fastify route of its method and path;
 * its role (and the refusal's audit entry) is enforced in the route's `onRequest` hook, its body
 * limit is Fastify's `bodyLimit` of the route, its handler runs on the raw request and response
 * (`reply.hijack()`: the answers stay byte for byte the gateway's own). The gateway calls it as a
 * request handler (`app.routing`) after its host and cross-site checks; TLS, the pages,
 * `/machines/*` and the WebSockets stay on the Node server.
 *
 * Paths match as the table says (`resolveRoute` on `new URL`'s pathname): Fastify routes that
 * pathname with each `%` escaped (find-my-way decodes percent escapes once, the table never did);
 * a pattern path is a wildcard route on its fixed prefix whose pattern is checked in its hook.
 * Fastify reads no body (POST, PUT and DELETE are declared bodyless): a route reads its own when
 * it needs it, up to its limit, as before; one that reads none leaves it to Node.
 */

/** The call a route's hook made, for its handler. */
interface Pending {
  url: URL;
  call?: RouteCall | GuardedCall;
  settle(err?: unknown): void;
}

/** The fixed start of a pattern path (`/^\/api\/sim\/(?<id>…)$/` → `/api/sim/`), or null. */
export function fixedPrefix(path: RegExp): string | null {
  // Anchored, case-sensitive, no alternation: the pattern's paths all start with its prefix.
  if (path.flags.includes('i') || path.source.includes('|')) return null;
  const m = /^\^((?:\\\/|\\\.|[a-z0-9-])+)([?*+{]?)/i.exec(path.source);
  if (!m?.[1] || m[2]) return null;
  const prefix = m[1].replace(/\\(.)/g, '$1');
  return prefix.endsWith('/') ? prefix : null;
}

/** The Fastify URL of a declared path: the path itself, or a wildcard on a pattern's prefix. */
export function fastifyUrl(r: ApiRoute): string {
  if (typeof r.path === 'string') {
    if (/[*:%]/.test(r.path)) throw new Error(`${routeKey(r)}: a path with * : or % cannot be routed`);
    return r.path;
  }
  const prefix = fixedPrefix(r.path);
  if (!prefix) throw new Error(`${routeKey(r)}: a pattern path needs a fixed prefix ending in /`);
  return `${prefix}*`;
}

/** The path find-my-way is given: `%` escaped, so its one decoding gives back the table's path. */
export function routingPath(pathname: string): string {
  return pathname.replaceAll('%', '%25');
}

export function fastifyApi(routes: readonly ApiRoute[], guard: Guard) {
  const pending = new WeakMap<IncomingMessage, Pending>();
  const app = Fastify({
    logger: false,
    exposeHeadRoutes: false,
    // The gateway's own path (set in `dispatch`) is what the router sees.
    rewriteUrl: (req) => {
      const p = pending.get(req);
      return p ? routingPath(p.url.pathname) : '/';
    },
    // A path find-my-way cannot decode (none after `routingPath`) answers as the table says.
    frameworkErrors: (err, request, reply) => unrouted(request, reply),
  });
  // Fastify parses no body: each route reads its own, lazily, up to its `bodyLimit`.
  for (const m of ['POST', 'PUT', 'DELETE']) app.addHttpMethod(m, { hasBody: false, overrideExisting: true });

  const state = (request: FastifyRequest): Pending => {
    const p = pending.get(request.raw);
    if (!p) throw new Error('an /api request not sent by the gateway');
    return p;
  };

  /** Answered by the table (404, 405; a route only where Fastify's routing could not say it). */
  async function unrouted(request: FastifyRequest, reply: FastifyReply): Promise<void> {
    void reply.hijack();
    const p = state(request);
    const { raw: req } = request;
    const res = reply.raw;
    const method = (req.method ?? 'GET').toUpperCase();
    try {
      const found = resolveRoute(routes, method, p.url.pathname);
      if (found.kind !== 'route') answerUnrouted(req, res, method, p.url.pathname, found);
      else {
        const call = guardRoute(
          guard,
          found.route,
          req,
          res,
          routeCall(req, found.route, p.url, found.params),
        );
        if (call) await runRoute(found.route, req, res, call);
      }
      p.settle();
    } catch (e) {
      p.settle(e);
    }
  }

  // Seen only when something escaped a hook (each answers its own): the gateway's error answer.
  app.setErrorHandler((err, request, reply) => {
    void reply.hijack();
    state(request).settle(err);
  });
  app.setNotFoundHandler(unrouted);

  const keys = new Map<string, ApiRoute>();
  for (const [i, route] of routes.entries()) {
    const url = fastifyUrl(route);
    const key = `${route.method} ${url}`;
    const twin = keys.get(key);
    if (twin) throw new Error(`${routeKey(route)} and ${routeKey(twin)} would be one Fastify route (${key})`);
    keys.set(key, route);
    // A path an earlier pattern of its method takes: the table answers it with that pattern.
    const shadow = routes
      .slice(0, i)
      .find(
        (r) =>
          r.method === route.method &&
          typeof route.path === 'string' &&
          r.path instanceof RegExp &&
          r.path.test(route.path),
      );
    if (shadow) throw new Error(`${routeKey(route)} is taken by ${routeKey(shadow)} before it`);
    app.route({
      method: route.method,
      url,
      bodyLimit: route.bodyLimit ?? DEFAULT_BODY_LIMIT,
      onRequest: async (request, reply) => {
        const p = state(request);
        const req = request.raw;
        const params: Record<string, string> = {};
        if (route.path instanceof RegExp) {
          const m = route.path.exec(p.url.pathname);
          if (!m) {
            await unrouted(request, reply);
            return;
          }
          for (const [k, v] of Object.entries(m.groups ?? {})) params[k] = v ?? '';
        }
        try {
          const call = routeCall(req, route, p.url, params, request.routeOptions.bodyLimit);
          const guarded = guardRoute(guard, route, req, reply.raw, call);
          if (guarded) p.call = guarded;
          else {
            void reply.hijack();
            p.settle();
          }
        } catch (e) {
          void reply.hijack();
          p.settle(e);
        }
      },
      handler: async (request, reply) => {
        void reply.hijack();
        const p = state(request);
        try {
          if (p.call) await runRoute(route, request.raw, reply.raw, p.call);
          p.settle();
        } catch (e) {
          p.settle(e);
        }
      },
    });
  }
  const ready = app.ready();

  /**
   * Answers one `/api/*` request (`url`: its URL as the gateway parsed it); settles when the route
   * has answered, rejects with what its handler threw (the gateway answers 400, 413 or 500).
   */
  async function dispatch(req: IncomingMessage, res: ServerResponse, url: URL): Promise<void> {
    await ready;
    return new Promise<void>((resolve, reject) => {
      pending.set(req, {
        url,
        settle: (err?: unknown) => {
          pending.delete(req);
          if (err === undefined) resolve();
          else reject(err instanceof Error ? err : new Error(String(err)));
        },
      });
      const original = req.url;
      try {
        app.routing(req, res);
      } finally {
        // Fastify routed on the rewritten path; the handlers and the server's log see the request's.
        req.url = original;
      }
    });
  }
  return Object.assign(dispatch, { app, ready });
}
