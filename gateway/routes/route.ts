import type { IncomingMessage, ServerResponse } from 'node:http';
import { roleAtLeast, type Role } from '../../src/fleet/types';
import type { AuditService, Principal, UsersService, Who } from '../services';
import { clientAddress, readJson, sendJson } from '../http-util';

/**
 * The `/api/*` surface as declared routes (issue 34 §2): each route says its method, path, the
 * role it needs, whether it changes state, its body limit and whether it writes the audit log.
 * Fastify answers them (fastify-api.ts: its routing matches as `resolveRoute` does) and enforces
 * the role once for every route that declares one (`guardRoute`). The host and cross-site
 * checks (csrf.ts) run before, in gateway.ts: every method outside GET/HEAD/OPTIONS needs the
 * console header there, which is what `changesState` says (route-table.test.ts holds them equal).
 */

export type HttpMethod = 'GET' | 'POST' | 'PUT' | 'DELETE';

/** The largest JSON body a route reads unless it says otherwise (http-util `readJson`). */
export const DEFAULT_BODY_LIMIT = 16 * 1024;

/** What every route gets besides the request and the response. */
export interface RouteCall {
  url: URL;
  /** The named groups of a pattern path; empty for an exact one. */
  params: Readonly<Record<string, string>>;
  address: string;
  method: HttpMethod;
  /** The request's JSON body, read up to the route's `bodyLimit` (`{}` when empty). */
  body(): Promise<unknown>;
}

/** A route that declares a role: the dispatcher checked it; who is asking. */
export interface GuardedCall extends RouteCall {
  who: Who;
  principal: Principal;
}

interface RouteBase {
  method: HttpMethod;
  /** An exact path, or a pattern whose named groups are the params. */
  path: string | RegExp;
  /** A path this route answers (a pattern's example): the route-table tests request it. */
  example?: string;
  /** Needs the console header (X-Shopdeck) and a same-origin request (csrf.ts, gateway.ts). */
  changesState: boolean;
  /** The most JSON it reads (bytes); absent: it reads no body. */
  bodyLimit?: number;
  /** Writes the audit log (its outcome, or its refusals). */
  audited: boolean;
  /**
   * A method that is not this route's on its path answers 405 with this error and an `Allow`
   * of the path's methods; absent: the dispatcher looks on (404 when nothing answers).
   */
  notAllowed?: string;
}

export interface PublicRoute extends RouteBase {
  /** No session needed: the handler decides what it answers to whom. */
  role: 'public';
  handle(req: IncomingMessage, res: ServerResponse, call: RouteCall): Promise<void> | void;
}

export interface GuardedRoute extends RouteBase {
  /** The least role: no session 401 (`needLogin`), a lower role 403 `{ error: refusal, needs }`. */
  role: Role;
  /** The 403 error; a function when it names who asked. */
  refusal?: string | ((p: Principal) => string);
  /** The session counts as active (`who(req, true)`). */
  touch?: boolean;
  /**
   * Refusals (401 and 403) are written to the audit log as `refused` entries with these fields.
   * Absent: a 403 (someone signed in asking past their role) is written with the request's path,
   * a 401 is not. Refusals are limited per user or address (refusals.ts).
   */
  auditRefusal?: (call: RouteCall) => { machine?: string; path: string };
  handle(req: IncomingMessage, res: ServerResponse, call: GuardedCall): Promise<void> | void;
}

export type ApiRoute = PublicRoute | GuardedRoute;

/** The params of `route` for `pathname`, or null when it is not the route's path. */
function matchPath(route: ApiRoute, pathname: string): Record<string, string> | null {
  if (typeof route.path === 'string') return route.path === pathname ? {} : null;
  const m = route.path.exec(pathname);
  if (!m) return null;
  const params: Record<string, string> = {};
  for (const [k, v] of Object.entries(m.groups ?? {})) params[k] = v ?? '';
  return params;
}

/** The key two routes must not share. */
export function routeKey(r: ApiRoute): string {
  return `${r.method} ${String(r.path)}`;
}

export type Guard = Pick<UsersService, 'who' | 'needLogin'> & Pick<AuditService, 'record'>;

/** What the table says of a request: the route that answers it, a 405, or nothing (404). */
export type Resolved =
  | { kind: 'route'; route: ApiRoute; params: Record<string, string> }
  | { kind: 'not-allowed'; error: string; allow: string }
  | { kind: 'none' };

/**
 * The table's answer for `method` on `pathname` (the path as `new URL` gives it): the first route
 * whose path matches and whose method is the request's; a path match of another method answers 405
 * where the route says so (`Allow`: the path's methods); nothing else 404. Fastify routes the
 * requests (fastify-api.ts); this decides its 404s and 405s and is what its routing must agree with.
 */
export function resolveRoute(routes: readonly ApiRoute[], method: string, pathname: string): Resolved {
  for (const route of routes) {
    const params = matchPath(route, pathname);
    if (!params) continue;
    if (route.method === method) return { kind: 'route', route, params };
    if (route.notAllowed === undefined) continue;
    // The path's methods (one route each): another of them may be the request's.
    const allow = routes.filter((r) => String(r.path) === String(route.path)).map((r) => r.method);
    if (allow.includes(method as HttpMethod)) continue;
    return { kind: 'not-allowed', error: route.notAllowed, allow: allow.join(', ') };
  }
  return { kind: 'none' };
}

/** Answers a request nothing in the table answers (the 405 or the 404 of `resolveRoute`). */
export function answerUnrouted(
  req: IncomingMessage,
  res: ServerResponse,
  method: string,
  pathname: string,
  found: Exclude<Resolved, { kind: 'route' }>,
): void {
  if (found.kind === 'not-allowed') {
    req.resume();
    sendJson(res, 405, { error: found.error }, { Allow: found.allow });
  } else sendJson(res, 404, { error: `no such endpoint: ${method} ${pathname}` });
}

/** What a route gets besides the request and the response (its body read up to `bodyLimit`). */
export function routeCall(
  req: IncomingMessage,
  route: ApiRoute,
  url: URL,
  params: Record<string, string>,
  bodyLimit = route.bodyLimit ?? DEFAULT_BODY_LIMIT,
): RouteCall {
  return {
    url,
    params,
    address: clientAddress(req),
    method: route.method,
    body: () => readJson(req, bodyLimit),
  };
}

/**
 * The role a route declares: a public route's call as it is; else who asks, or null when the
 * request was answered here (401 `needLogin`, 403 `{ error, needs }`), its refusal written to the
 * audit log as the route declares (`auditRefusal`; a 403 by default with the request's path).
 */
export function guardRoute(
  guard: Guard,
  route: ApiRoute,
  req: IncomingMessage,
  res: ServerResponse,
  call: RouteCall,
): RouteCall | GuardedCall | null {
  if (route.role === 'public') return call;
  const { who, needLogin, record } = guard;
  const w = who(req, route.touch === true);
  const p = w.principal;
  const refuse = (error: string, signedIn: boolean): void => {
    req.resume();
    const where = route.auditRefusal?.(call) ?? (signedIn ? { path: call.url.pathname } : null);
    if (!where) return;
    record({
      type: 'refused',
      result: 'refused',
      user: p?.name ?? 'nobody',
      onBehalfOf: p?.onBehalfOf,
      source: 'gateway',
      machine: where.machine,
      method: route.method,
      path: where.path,
      role: route.role,
      address: call.address,
      error,
    });
  };
  if (!p) {
    refuse(w.expired ? 'session expired' : 'not logged in', false);
    needLogin(res, w);
    return null;
  }
  if (!roleAtLeast(p.role, route.role)) {
    const r = route.refusal;
    const error = typeof r === 'function' ? r(p) : (r ?? `this needs a ${route.role}`);
    refuse(error, true);
    sendJson(res, 403, { error, needs: route.role });
    return null;
  }
  return { ...call, who: w, principal: p };
}

/** Runs a route's handler with the call `guardRoute` gave. */
export async function runRoute(
  route: ApiRoute,
  req: IncomingMessage,
  res: ServerResponse,
  call: RouteCall | GuardedCall,
): Promise<void> {
  if (route.role === 'public') await route.handle(req, res, call);
  else if ('principal' in call) await route.handle(req, res, call);
}

/**
 * The table's own dispatcher (before Fastify): match, role, handler. Kept as the reference the
 * benchmark (tests/bench/api-dispatch.ts) measures Fastify against; the gateway uses fastify-api.ts.
 */
export function dispatcher(routes: readonly ApiRoute[], guard: Guard) {
  return async function dispatch(req: IncomingMessage, res: ServerResponse, url: URL): Promise<void> {
    const method = (req.method ?? 'GET').toUpperCase();
    const found = resolveRoute(routes, method, url.pathname);
    if (found.kind !== 'route') {
      answerUnrouted(req, res, method, url.pathname, found);
      return;
    }
    const call = guardRoute(guard, found.route, req, res, routeCall(req, found.route, url, found.params));
    if (call) await runRoute(found.route, req, res, call);
  };
}
