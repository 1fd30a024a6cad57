import type { IncomingMessage, ServerResponse } from 'node:http';
import { roleAtLeast, type Role } from '../../src/fleet/types';
import type { AuditService, Principal, UsersService, Who } from '../services';
import { clientAddress, readJson, sendJson } from '../http-util';

/**
 * The `/api/*` surface as declared routes (issue 34 §2): each route says its method, path, the
 * role it needs, whether it changes state, its body limit and whether it writes the audit log;
 * `dispatch` enforces the role once for every route that declares one. The host and cross-site
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

type Guard = Pick<UsersService, 'who' | 'needLogin'> & Pick<AuditService, 'record'>;

/**
 * The dispatcher: the first route whose path matches and whose method is the request's answers;
 * a path match of another method answers 405 where the route says so; nothing else 404.
 */
export function dispatcher(routes: readonly ApiRoute[], guard: Guard) {
  const { who, needLogin, record } = guard;
  return async function dispatch(req: IncomingMessage, res: ServerResponse, url: URL): Promise<void> {
    const method = (req.method ?? 'GET').toUpperCase();
    for (const route of routes) {
      const params = matchPath(route, url.pathname);
      if (!params) continue;
      if (route.method !== method) {
        if (route.notAllowed === undefined) continue;
        // The path's methods (one route each): another of them may be the request's.
        const allow = routes.filter((r) => String(r.path) === String(route.path)).map((r) => r.method);
        if (allow.includes(method as HttpMethod)) continue;
        req.resume();
        sendJson(res, 405, { error: route.notAllowed }, { Allow: allow.join(', ') });
        return;
      }
      const call: RouteCall = {
        url,
        params,
        address: clientAddress(req),
        method: route.method,
        body: () => readJson(req, route.bodyLimit ?? DEFAULT_BODY_LIMIT),
      };
      if (route.role === 'public') {
        await route.handle(req, res, call);
        return;
      }
      const w = who(req, route.touch === true);
      const p = w.principal;
      const refuse = (error: string, signedIn: boolean): void => {
        req.resume();
        const where = route.auditRefusal?.(call) ?? (signedIn ? { path: url.pathname } : null);
        if (!where) return;
        record({
          type: 'refused',
          result: 'refused',
          user: p?.name ?? 'nobody',
          onBehalfOf: p?.onBehalfOf,
          source: 'gateway',
          machine: where.machine,
          method,
          path: where.path,
          role: route.role,
          address: call.address,
          error,
        });
      };
      if (!p) {
        refuse(w.expired ? 'session expired' : 'not logged in', false);
        needLogin(res, w);
        return;
      }
      if (!roleAtLeast(p.role, route.role)) {
        const r = route.refusal;
        const error = typeof r === 'function' ? r(p) : (r ?? `this needs a ${route.role}`);
        refuse(error, true);
        sendJson(res, 403, { error, needs: route.role });
        return;
      }
      await route.handle(req, res, { ...call, who: w, principal: p });
      return;
    }
    sendJson(res, 404, { error: `no such endpoint: ${method} ${url.pathname}` });
  };
}
