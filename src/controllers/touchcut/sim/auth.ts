import { jsonResponse } from '../../../fleet/sim';
import { TOUCHCUT_PRIVILEGES } from '../client';
import { defaultUsers, type SimUser } from '../sim-users';
import { MANUAL_EXAMPLE_API_KEY } from './data/manual';
import { TouchcutSimWorld } from './world';

/**
 * The simulated TouchCut's users, groups and logins: groups may carry an API key
 * (`X-TouchCut-API-Key`); `POST auth` gives a JWT (`Authorization: Bearer` or the `__Secure-jwt`
 * cookie) that expires, and a JWT takes precedence over a key; `auth/change-password` needs a JWT.
 */

export const SIM_WEB_ACCESS = 'Web Access';
const ALL_PRIVILEGES = [SIM_WEB_ACCESS, ...TOUCHCUT_PRIVILEGES];

export interface SimGroup {
  name: string;
  privileges: string[];
  apiKey: string | null;
}

/** Simulated API key of the "Monitor" group (what a gateway would hold for a demo machine). */
export const SIM_MONITOR_API_KEY = 'SIMULATED0TOUCHCUT0MONITOR0KEY00000000000';

export function defaultGroups(): SimGroup[] {
  return [
    { name: 'Administrator', privileges: [...ALL_PRIVILEGES], apiKey: null },
    // The manual's dialog ("Modify User Group: User") with its example key.
    {
      name: 'User',
      privileges: [
        SIM_WEB_ACCESS,
        'Monitor System',
        'Add Remove Tools',
        'Add Remove Materials',
        'Add Remove Tool Processes',
        'Modify General Settings Advanced',
        'Modify Tools Advanced',
        'Modify Tool Processes Advanced',
        'Modify Tuning',
        'Confirm Maintenance Done',
        'Modify Dross Bin Settings',
        'Modify Current User',
        'Modify General Settings',
      ],
      apiKey: MANUAL_EXAMPLE_API_KEY,
    },
    { name: 'Monitor', privileges: [SIM_WEB_ACCESS, 'Monitor System'], apiKey: SIM_MONITOR_API_KEY },
    // Web access but no "Monitor System": status works, monitor and screenshot answer 403.
    { name: 'Office', privileges: [SIM_WEB_ACCESS, 'Modify Current User'], apiKey: null },
    { name: 'Guest', privileges: [], apiKey: null },
  ];
}

/** JWT lifetime in the simulator (TouchCut's own lifetime is not documented). */
export const SIM_JWT_TTL_MS = 15 * 60_000;
/** How long the simulated application stays "not ready" after a simulated restart. */
export const SIM_RESTART_MS = 8_000;

function b64url(s: string): string {
  const b = typeof btoa === 'function' ? btoa(s) : Buffer.from(s, 'binary').toString('base64');
  return b.replace(/=+$/, '').replace(/\+/g, '-').replace(/\//g, '_');
}

export const empty = (status: number) => new Response(null, { status });
const tcError = (status: number, code: string, msg: string) =>
  jsonResponse({ code, msg }, status, 'application/json; charset=utf-8');
export const ok = (body: unknown) => jsonResponse(body, 200, 'application/json; charset=utf-8');

export abstract class TouchcutSimAuth extends TouchcutSimWorld {
  readonly users: SimUser[] = defaultUsers();
  readonly groups: SimGroup[] = defaultGroups();
  /** Issued JWTs: token -> user and expiry. */
  readonly tokens = new Map<string, { user: string; exp: number }>();
  notReadyUntil = 0;
  breakJwt = false;
  /**
   * Demo stand-in for the gateway. A simulated machine has no secrets in the machines file, so
   * the gateway that answers it from this simulator adds no key; the simulator plays that part: a request with neither a JWT nor a key is treated as carrying the "Monitor"
   * group's key (as a gateway with a configured apiKey would send). The control "Revoke the
   * console's API key" turns this off to show the needs-login path. Off by default (tests).
   */
  gatewayKeyStandIn = false;
  /** JWT lifetime (tests shorten it). */
  jwtTtlMs = SIM_JWT_TTL_MS;

  expireAllTokens(): void {
    for (const [, t] of this.tokens) t.exp = 0;
  }

  restartApp(): void {
    this.notReadyUntil = this.now() + SIM_RESTART_MS;
  }

  // ---- auth ---------------------------------------------------------------------------------

  private issueToken(user: string): string {
    const iat = this.now();
    const exp = iat + this.jwtTtlMs;
    const header = b64url(JSON.stringify({ alg: 'HS256', typ: 'JWT' }));
    const payload = b64url(
      JSON.stringify({
        sub: user,
        iat: Math.floor(iat / 1000),
        exp: Math.floor(exp / 1000),
        jti: Math.random(),
      }),
    );
    const token = `${header}.${payload}.${b64url(`simulated-signature-${this.tokens.size}`)}`;
    this.tokens.set(token, { user, exp });
    return token;
  }

  private group(name: string): SimGroup | undefined {
    return this.groups.find((g) => g.name === name);
  }

  /**
   * Who is asking: a JWT (header or `__Secure-jwt` cookie) takes precedence over an API key. Null
   * means 401.
   */
  protected principal(
    req: Request,
  ): { user: string | null; privileges: string[]; via: 'jwt' | 'key' } | null {
    const auth = req.headers.get('authorization') ?? '';
    const cookie = /(?:^|;\s*)__Secure-jwt=([^;]+)/.exec(req.headers.get('cookie') ?? '')?.[1];
    const jwt = /^Bearer\s+(.+)$/i.exec(auth)?.[1]?.trim() ?? cookie;
    if (jwt) {
      const t = this.tokens.get(jwt);
      if (!t || t.exp <= this.now()) return null;
      const u = this.users.find((x) => x.username === t.user);
      const g = u ? this.group(u.group) : undefined;
      return { user: t.user, privileges: g?.privileges ?? [], via: 'jwt' };
    }
    const key =
      req.headers.get('x-touchcut-api-key')?.trim() ||
      (this.gatewayKeyStandIn ? SIM_MONITOR_API_KEY : undefined);
    if (key) {
      const g = this.groups.find((x) => x.apiKey !== null && x.apiKey === key);
      if (!g) return null;
      return { user: null, privileges: g.privileges, via: 'key' };
    }
    return null;
  }

  private async params(req: Request, query: URLSearchParams): Promise<URLSearchParams> {
    const out = new URLSearchParams(query);
    const text = await req.text();
    if (!text.trim()) return out;
    if (text.trim().startsWith('{')) {
      try {
        for (const [k, v] of Object.entries(JSON.parse(text) as Record<string, unknown>)) {
          if (v !== null && v !== undefined) out.set(k, String(v));
        }
      } catch {
        /* not JSON: ignore */
      }
      return out;
    }
    for (const [k, v] of new URLSearchParams(text)) out.set(k, v);
    return out;
  }

  protected async auth(req: Request, query: URLSearchParams): Promise<Response> {
    const p = await this.params(req, query);
    const username = p.get('username');
    const password = p.get('password');
    if (!username) return tcError(400, '1003', 'Required parameter missing: username');
    if (!password) return tcError(400, '1003', 'Required parameter missing: password');
    if (this.now() < this.notReadyUntil) return tcError(400, '100', 'Application not ready');
    const u = this.users.find((x) => x.username.toLowerCase() === username.toLowerCase());
    if (!u) return tcError(400, '101', 'Invalid Username');
    if (u.password !== password) return tcError(400, '102', 'Invalid Password');
    if (!this.group(u.group)?.privileges.includes(SIM_WEB_ACCESS)) return empty(401);
    if (this.breakJwt) return tcError(500, '2000', 'Error creating JWT');
    return ok({ success: 'true', token: this.issueToken(u.username) });
  }

  protected async changePassword(req: Request, query: URLSearchParams): Promise<Response> {
    const who = this.principal(req);
    // "Some REST API requests are not available via API Keys, such as rest/v1/auth/change-password".
    if (!who || who.via !== 'jwt') return empty(401);
    const p = await this.params(req, query);
    const oldPw = p.get('old-password');
    const newPw = p.get('new-password');
    const confirm = p.get('confirm-password');
    if (!oldPw) return tcError(400, '1003', 'Required parameter missing: old-password');
    if (!newPw) return tcError(400, '1003', 'Required parameter missing: new-password');
    if (!confirm) return tcError(400, '1003', 'Required parameter missing: confirm-password');
    if (confirm !== newPw) return tcError(400, '1002', 'Invalid parameter: confirm-password');
    if (this.now() < this.notReadyUntil) return tcError(400, '100', 'Application not ready');
    const u = this.users.find((x) => x.username === who.user);
    if (!u) return tcError(400, '101', 'Invalid Username');
    if (!who.privileges.includes('Modify Current User')) return empty(403);
    if (u.password !== oldPw) return tcError(400, '102', 'Invalid Password');
    if (this.breakJwt) return tcError(500, '2000', 'Error creating JWT');
    u.password = newPw;
    return ok({ success: 'true', token: this.issueToken(u.username) });
  }
}
