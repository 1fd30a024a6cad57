import { METHODS, type IncomingMessage, type ServerResponse } from 'node:http';
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
 * a pattern path is a wildcard route on its fixed prefix, answered where the table says so (its
 * hook asks `resolveRoute`); a fixed path the table would answer otherwise is refused at start.
 * Fastify reads no body (every method is declared bodyless): a route reads its own when
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
  const m = /^\^((?:\\[/.-]|[a-z0-9-])+)([?*+{]?)/i.exec(path.source);
  if (!m?.[1]) return null;
  // The literal characters; the last one is optional when a quantifier follows it.
  const chars = m[1].match(/\\.|./g) ?? [];
  if (m[2]) chars.pop();
  const literal = chars.map((c) => c.replace(/^\\/, '')).join('');
  const cut = literal.lastIndexOf('/');
  return cut > 0 ? literal.slice(0, cut + 1) : null;
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

/** The methods Fastify reads a body of (fastify.js `kSupportedHTTPMethods.bodywith`). */
const BODY_METHODS = ['DELETE', 'OPTIONS', 'PATCH', 'PUT', 'POST', 'QUERY'];

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
  // Fastify parses no body (no method has one for it, no parser reads one): each route reads its
  // own, lazily, up to its `bodyLimit`; one it does not read is left to Node as before.
  for (const m of BODY_METHODS.filter((x) => METHODS.includes(x)))
    app.addHttpMethod(m, { hasBody: false, overrideExisting: true });
  app.removeAllContentTypeParsers();
  app.addContentTypeParser('*', (request, payload, done) => done(null));

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
  for (const route of routes) {
    const url = fastifyUrl(route);
    const key = `${route.method} ${url}`;
    const twin = keys.get(key);
    if (twin) throw new Error(`${routeKey(route)} and ${routeKey(twin)} would be one Fastify route (${key})`);
    keys.set(key, route);
    // Fastify answers a fixed path with its route: the table must too (no earlier pattern takes
    // it, nor answers it 405).
    if (typeof route.path === 'string') {
      const found = resolveRoute(routes, route.method, route.path);
      if (found.kind !== 'route' || found.route !== route)
        throw new Error(`${routeKey(route)} is answered by an earlier route of the table`);
    }
    app.route({
      method: route.method,
      url,
      bodyLimit: route.bodyLimit ?? DEFAULT_BODY_LIMIT,
      onRequest: async (request, reply) => {
        const p = state(request);
        const req = request.raw;
        let params: Record<string, string> = {};
        if (route.path instanceof RegExp) {
          // A pattern's wildcard: the route answers where the table says it does, else the table.
          const found = resolveRoute(routes, route.method, p.url.pathname);
          if (found.kind !== 'route' || found.route !== route) {
            await unrouted(request, reply);
            return;
          }
          params = found.params;
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
          if (!p.call) throw new Error(`${routeKey(route)}: no call from its hook`);
          await runRoute(route, request.raw, reply.raw, p.call);
          p.settle();
        } catch (e) {
          p.settle(e);
        }
      },
    });
  }
  const ready = new Promise<void>((resolve, reject) => {
    app.ready((err) => (err ? reject(err) : resolve()));
  });
  ready.catch(() => undefined); // awaited (and thrown) by each request

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
