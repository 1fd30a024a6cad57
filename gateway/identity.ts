import type { IncomingMessage, ServerResponse } from 'node:http';
import type { WebSocket } from 'ws';
import { roleAtLeast } from '../src/fleet/types';
import { SESSION_COOKIE, type SessionStore } from './auth';
import { clientAddress, parseCookies, sendJson } from './http-util';
import type { GatewayOptions } from './options';
import type { AuditService, LiveSocket, Principal, UsersService, Who } from './services';
import type { UserDirectory } from './users';

/**
 * Who is asking (context.ts): the principal of a request from its session cookie, the session's
 * answer, the cookie, the machine list check, and the re-check of bridged sockets whenever the
 * users file changes or a session ends.
 */

export interface IdentityDeps {
  opts: Pick<GatewayOptions, 'openOnNetwork'>;
  users: UserDirectory;
  sessions: SessionStore;
  record: AuditService['record'];
  liveSockets: Map<WebSocket, LiveSocket>;
}

export type Identity = Pick<
  UsersService,
  'who' | 'sessionBody' | 'cookie' | 'mayUseMachine' | 'needLogin' | 'revalidateSockets'
>;

/** The principal's machine list has the machine (null: every machine). */
export function mayUseMachine(p: Principal, id: string): boolean {
  return p.machines === null || p.machines.includes(id);
}

export function createIdentity({ opts, users, sessions, record, liveSockets }: IdentityDeps): Identity {
  // Sessions kept from before a restart are checked against the users file at the first request.
  let seenUsers = Number.NaN;
  /**
   * Sessions follow the users file as soon as it changes (any request notices): a session takes
   * its user's new role (and with it the idle timeout), an unlock ends when the tablet's user is
   * no longer an operator, a removed user's sessions end; then bridged sockets are re-checked.
   */
  function followUsersFile(): void {
    const generation = users.generation;
    if (generation === seenUsers) return;
    seenUsers = generation;
    const seen = new Set<string>();
    for (const s of sessions.list()) {
      const u = users.find(s.user);
      if (!u) {
        const n = sessions.dropUser(s.user);
        record({
          type: 'user-removed',
          result: 'ok',
          user: s.user,
          source: 'gateway',
          detail: `no longer in the users file: ${n} session${n === 1 ? '' : 's'} ended`,
        });
        continue;
      }
      if (u.role !== s.role) {
        if (!seen.has(u.name))
          record({
            type: 'role-change',
            result: 'ok',
            user: u.name,
            role: u.role,
            source: 'gateway',
            detail: `${s.role} → ${u.role} (seen by the gateway on a live session: idle timeout now ${sessions.idleSeconds(u.role)} s)`,
          });
        seen.add(u.name);
        s.role = u.role;
        sessions.save(s);
      }
      if (s.elevation && u.role !== 'operator') {
        record({
          type: 'elevate-end',
          result: 'ok',
          user: s.elevation.supervisor,
          onBehalfOf: u.name,
          source: 'gateway',
          detail: `${u.name} is no longer an operator`,
        });
        s.elevation = null;
      }
    }
    revalidateSockets();
  }

  function who(req: IncomingMessage, touch: boolean): Who {
    if (users.mode === 'open') {
      return {
        mode: 'open',
        principal: { name: 'anonymous', role: 'supervisor', machines: null },
        session: null,
        expired: false,
      };
    }
    followUsersFile();
    const token = parseCookies(req.headers.cookie)[SESSION_COOKIE];
    const s = sessions.get(token, touch);
    if (s && 'expired' in s) {
      record({
        type: 'session-expired',
        result: 'ok',
        user: s.expired.user,
        source: 'gateway',
        address: clientAddress(req),
        detail: `no activity for ${sessions.idleSeconds(s.expired.role)} s`,
      });
      return { mode: 'secured', principal: null, session: null, expired: true };
    }
    if (!s) return { mode: 'secured', principal: null, session: null, expired: false };
    const u = users.find(s.user);
    if (!u) {
      sessions.dropUser(s.user);
      return { mode: 'secured', principal: null, session: null, expired: false };
    }
    if (s.elevation) {
      const sup = users.find(s.elevation.supervisor);
      if (sup && sup.role === 'supervisor' && u.role === 'operator') {
        return {
          mode: 'secured',
          principal: { name: sup.name, role: 'supervisor', machines: sup.machines, onBehalfOf: u.name },
          session: s,
          expired: false,
        };
      }
      s.elevation = null;
    }
    return {
      mode: 'secured',
      principal: { name: u.name, role: u.role, machines: u.machines },
      session: s,
      expired: false,
    };
  }

  /**
   * `GET /api/session`. `user` is who the gateway acts as right now: during a PIN elevation
   * the supervisor, with the operator whose tablet it is in `elevation.operator`.
   */
  function sessionBody(w: Who): unknown {
    const u = w.session ? users.find(w.session.user) : null;
    const p = w.mode === 'secured' ? w.principal : null;
    return {
      mode: w.mode,
      ...(w.mode === 'open' ? { openOnNetwork: opts.openOnNetwork === true } : {}),
      user: p ? { name: p.name, role: p.role, machines: p.machines } : null,
      idleTimeoutS: u ? sessions.idleSeconds(w.session?.role ?? u.role) : null,
      elevation:
        w.session?.elevation && p?.onBehalfOf && u
          ? {
              supervisor: w.session.elevation.supervisor,
              until: new Date(w.session.elevation.until).toISOString(),
              operator: { name: u.name, role: u.role, machines: u.machines },
            }
          : null,
      expired: w.expired,
    };
  }

  function cookie(req: IncomingMessage, token: string, maxAge?: number): string {
    const secure = (req.socket as { encrypted?: boolean }).encrypted ? '; Secure' : '';
    const age = maxAge !== undefined ? `; Max-Age=${maxAge}` : '';
    return `${SESSION_COOKIE}=${token}; Path=/; HttpOnly; SameSite=Strict${secure}${age}`;
  }

  function needLogin(res: ServerResponse, w: Who): void {
    sendJson(res, 401, {
      error: w.expired ? 'your session expired: log in again' : 'log in first',
      needs: 'viewer',
      login: true,
    });
  }

  function revalidateSockets(): void {
    if (users.mode === 'open') return;
    for (const [sock, live] of liveSockets) {
      const why = socketProblem(live);
      if (why) {
        liveSockets.delete(sock);
        live.close(4401, why);
      }
    }
  }

  /** Why a bridged socket may no longer stay open, or null. */
  function socketProblem(live: LiveSocket): string | null {
    const s = sessions.get(live.token ?? undefined, false);
    if (!s) return 'logged out';
    if ('expired' in s) return 'session expired';
    const u = users.find(s.user);
    if (!u) return 'user removed';
    const name = s.elevation ? s.elevation.supervisor : u.name;
    const p = s.elevation ? users.find(s.elevation.supervisor) : u;
    if (!p) return 'user removed';
    if (!roleAtLeast(s.elevation ? 'supervisor' : p.role, live.needs))
      return `${name} no longer has the ${live.needs} role`;
    if (!mayUseMachine({ name, role: p.role, machines: p.machines }, live.machine))
      return `${name} may no longer use ${live.machine}`;
    return null;
  }

  return { who, sessionBody, cookie, mayUseMachine, needLogin, revalidateSockets };
}
