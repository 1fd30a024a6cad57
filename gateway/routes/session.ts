import type { ServerResponse } from 'node:http';
import { z } from 'zod';
import { LoginHistory, SESSION_COOKIE, type LimitKey } from '../auth';
import type { AuditService, ConfigService, UsersService, Who } from '../services';
import { parseCookies, sendJson } from '../http-util';
import { LOGOUT_CLEAR_SITE_DATA } from '../page-headers';
import { PIN_RULE, checkSecret } from '../users';
import { DEFAULT_BODY_LIMIT, type ApiRoute, type RouteCall } from './route';

/**
 * The session: who is logged in, logging in and out, and a supervisor's PIN unlock of an
 * operator's tablet (`elevate`). Every route is public at the dispatcher: each answers a missing
 * session its own way (the session's state, 401, or a refusal written to the audit log).
 */

const loginSchema = z.object({ name: z.string().min(1).max(64), password: z.string().min(1).max(1024) });
const elevateSchema = z.object({ name: z.string().min(1).max(64), pin: z.string().min(1).max(64) });

function tooMany(res: ServerResponse, error: string, retryAfterS: number): void {
  sendJson(res, 429, { error, retryAfterS }, { 'Retry-After': String(retryAfterS) });
}

export type SessionServices = Pick<
  UsersService,
  | 'users'
  | 'sessions'
  | 'limiter'
  | 'who'
  | 'sessionBody'
  | 'cookie'
  | 'needLogin'
  | 'elevationMs'
  | 'revalidateSockets'
> &
  Pick<AuditService, 'record'> &
  Pick<ConfigService, 'now'>;

export function sessionRoutes(s: SessionServices): ApiRoute[] {
  const {
    users,
    sessions,
    limiter,
    record,
    who,
    sessionBody,
    cookie,
    needLogin,
    now,
    elevationMs,
    revalidateSockets,
  } = s;
  const limits = limiter.opts;

  /** Where each user logged in from: the per-user backstop spares those addresses. */
  const logins = new LoginHistory(now);
  /** PIN locks already written to the audit log (limiter key → when), one entry per lock. */
  const locksNoted = new Map<string, number>();

  /**
   * A login attempt counts per (user, address) and per address; per user only from addresses
   * the user never logged in from (a backstop against many addresses that cannot lock the real
   * user out of their tablet).
   */
  function loginKeys(name: string, address: string): LimitKey[] {
    const keys: LimitKey[] = [
      { key: `login:${JSON.stringify([name, address])}`, limit: limits.perUser },
      { key: `addr:${address}`, limit: limits.perAddress },
    ];
    if (!logins.knows(name, address)) keys.push({ key: `user:${name}`, limit: limits.perUserTotal });
    return keys;
  }

  /** The tablets (operator, address) each supervisor's PIN unlocked: the per-PIN backstop spares them. */
  const unlocks = new LoginHistory(now);
  const tabletOf = (operator: string, address: string): string => JSON.stringify([operator, address]);

  /**
   * A wrong PIN counts against whoever tried it: the tablet (the operator's session at its
   * address: 5, then that tablet may try no more), the operator account from any address, and the
   * address. Per supervisor only as a backstop against guessing one PIN from many operators or
   * addresses, and only on tablets that supervisor never unlocked: an operator's wrong PINs
   * never stop the supervisor's PIN on another tablet, nor the supervisor's password.
   */
  function pinKeys(name: string, operator: string, address: string): LimitKey[] {
    const keys: LimitKey[] = [
      { key: `pin-tablet:${tabletOf(operator, address)}`, limit: limits.perPin },
      { key: `pin-op:${operator}`, limit: limits.perPinOperator },
      // Its own counter: wrong PINs never lock the logins from that address.
      { key: `pin-addr:${address}`, limit: limits.perAddress },
    ];
    if (!unlocks.knows(name, tabletOf(operator, address)))
      keys.push({ key: `pin:${name}`, limit: limits.perPinTotal });
    return keys;
  }

  /** The refusal (audit, answer) when `key` of `pinKeys` is at its limit. */
  function pinRefusal(key: string, name: string, operator: string, retryAfterS: number): [string, string] {
    if (key.startsWith('pin-tablet:'))
      return [
        `this tablet (${operator} at this address) is locked: too many wrong PINs`,
        `too many wrong PINs on this tablet: try again in ${retryAfterS} s`,
      ];
    if (key.startsWith('pin-op:'))
      return [
        `${operator} is locked from PIN unlocks: too many wrong PINs`,
        `too many wrong PINs by ${operator}: try again in ${retryAfterS} s`,
      ];
    if (key.startsWith('pin:'))
      return [
        `the PIN of ${name} is locked on tablets ${name} never unlocked: too many wrong PINs from anywhere`,
        `too many wrong PINs for ${name}: on this tablet the PIN is locked, try again in ${retryAfterS} s`,
      ];
    return ['too many failed PINs', `too many failed PINs: try again in ${retryAfterS} s`];
  }

  /** After a wrong PIN: what became locked by it, the first time each lock happens (the audit). */
  function pinLockNote(name: string, operator: string, address: string): string {
    const t = now();
    const notes: string[] = [];
    const locks: Array<[LimitKey, string]> = [
      [
        { key: `pin-tablet:${tabletOf(operator, address)}`, limit: limits.perPin },
        `this tablet (${operator} at ${address}) may try no PIN for up to ${Math.round(limits.windowMs / 60_000)} min after ${limits.perPin} wrong PINs (other tablets and the supervisors' PINs are not affected)`,
      ],
      [
        { key: `pin-op:${operator}`, limit: limits.perPinOperator },
        `${operator} may try no PIN for up to ${Math.round(limits.windowMs / 60_000)} min after ${limits.perPinOperator} wrong PINs from any address`,
      ],
      [
        { key: `pin:${name}`, limit: limits.perPinTotal },
        `the PIN of ${name} is refused for up to ${Math.round(limits.windowMs / 60_000)} min on tablets ${name} never unlocked, after ${limits.perPinTotal} wrong PINs from anywhere (tablets ${name} unlocked before and the password still work)`,
      ],
    ];
    for (const [key, note] of locks) {
      if (limiter.count(key) < key.limit) continue;
      const noted = locksNoted.get(key.key);
      if (noted !== undefined && t - noted < limits.windowMs) continue;
      if (locksNoted.size > 1000)
        for (const [k, at] of locksNoted) if (t - at >= limits.windowMs) locksNoted.delete(k);
      locksNoted.set(key.key, t);
      notes.push(note);
    }
    return notes.map((n) => `; ${n}`).join('');
  }

  /**
   * Reads a login's or an unlock's body; a body that is not `schema` is answered 400 with `shape`
   * (what to send) and gives null.
   */
  async function readAttempt<T>(
    res: ServerResponse,
    call: RouteCall,
    schema: z.ZodType<T>,
    shape: string,
  ): Promise<T | null> {
    const body = schema.safeParse(await call.body());
    if (body.success) return body.data;
    sendJson(res, 400, { error: shape });
    return null;
  }

  /**
   * A password login and a supervisor's PIN unlock alike, once the body is read: the attempt is
   * counted BEFORE the slow comparison (concurrent guesses cannot all pass the check); a key at
   * its limit is refused (429, `Retry-After`), a wrong secret answered 401, each written to the
   * audit log as `type` (`refused` / `failed`). Gives who the secret belongs to (the counted
   * attempt given back), or null when it was answered here.
   */
  async function attempt<U>(
    res: ServerResponse,
    a: {
      type: 'login-failed' | 'elevate-failed';
      /** Who the attempt names. */
      name: string;
      /** The operator whose tablet a PIN unlocks. */
      onBehalfOf?: string;
      address: string;
      keys: LimitKey[];
      /** The audit's error and the answer when `key` is at its limit. */
      limited(key: string, retryAfterS: number): [string, string];
      /** Compares the secret: its owner, or the audit's error and the answer. */
      verify(): Promise<{ ok: true; owner: U } | { ok: false; error: string; answer: string }>;
      /** Added to a failure's audit entry (what became locked by it). */
      failNote?(): string;
    },
  ): Promise<U | null> {
    const { type, name, address } = a;
    const by = a.onBehalfOf !== undefined ? { onBehalfOf: a.onBehalfOf } : {};
    const slot = limiter.reserve(a.keys);
    if (!slot.ok) {
      const [error, answer] = a.limited(slot.key, slot.retryAfterS);
      record({ type, result: 'refused', user: name, ...by, source: 'gateway', address, error });
      tooMany(res, answer, slot.retryAfterS);
      return null;
    }
    const v = await a.verify();
    if (!v.ok) {
      const error = v.error + (a.failNote?.() ?? '');
      record({ type, result: 'failed', user: name, ...by, source: 'gateway', address, error });
      sendJson(res, 401, { error: v.answer });
      return null;
    }
    slot.release();
    return v.owner;
  }

  return [
    {
      method: 'GET',
      path: '/api/session',
      role: 'public',
      changesState: false,
      audited: false,
      handle(req, res) {
        sendJson(res, 200, sessionBody(who(req, false)));
      },
    },
    {
      method: 'POST',
      path: '/api/session/activity',
      role: 'public',
      changesState: true,
      audited: false,
      handle(req, res) {
        const w = who(req, true);
        sendJson(res, w.principal ? 200 : 401, sessionBody(w));
      },
    },
    {
      method: 'POST',
      path: '/api/login',
      role: 'public',
      changesState: true,
      bodyLimit: DEFAULT_BODY_LIMIT,
      audited: true,
      async handle(req, res, call) {
        const { address } = call;
        if (users.mode === 'open') {
          sendJson(res, 400, { error: 'open mode: there are no users to log in as' });
          return;
        }
        const body = await readAttempt(res, call, loginSchema, 'send { "name": …, "password": … }');
        if (!body) return;
        const { name, password } = body;
        const keys = loginKeys(name, address);
        const u = await attempt(res, {
          type: 'login-failed',
          name,
          address,
          keys,
          limited: (key, retryAfterS) => [
            key.startsWith('user:')
              ? 'too many failed logins for this user from addresses it never logged in from'
              : 'too many failed logins',
            `too many failed logins: try again in ${retryAfterS} s`,
          ],
          async verify() {
            const found = users.find(name);
            const ok = await checkSecret(password, found?.passwordHash ?? users.dummyHash('password'));
            return found && ok
              ? { ok: true, owner: found }
              : { ok: false, error: 'wrong name or password', answer: 'wrong name or password' };
          },
        });
        if (!u) return;
        limiter.clear(keys[0]!.key);
        logins.remember(u.name, address);
        // The login replaces whatever session this browser had: none is left behind.
        const previous = parseCookies(req.headers.cookie)[SESSION_COOKIE];
        if (previous) {
          sessions.delete(previous);
          revalidateSockets();
        }
        const s = sessions.create(u.name, u.role);
        record({ type: 'login', result: 'ok', user: u.name, role: u.role, source: 'gateway', address });
        const w: Who = {
          mode: 'secured',
          principal: { name: u.name, role: u.role, machines: u.machines },
          session: s,
          expired: false,
        };
        sendJson(res, 200, sessionBody(w), { 'Set-Cookie': cookie(req, s.token) });
      },
    },
    {
      method: 'POST',
      path: '/api/logout',
      role: 'public',
      changesState: true,
      audited: true,
      handle(req, res, call) {
        const { address } = call;
        const token = parseCookies(req.headers.cookie)[SESSION_COOKIE];
        const s = sessions.get(token, false);
        if (token) sessions.delete(token);
        revalidateSockets();
        if (s && !('expired' in s))
          record({ type: 'logout', result: 'ok', user: s.user, source: 'gateway', address });
        sendJson(
          res,
          200,
          { mode: users.mode, user: null, idleTimeoutS: null, elevation: null, expired: false },
          {
            'Set-Cookie': cookie(req, '', 0),
            // Nothing of the session stays on a shared tablet: the HTTP cache, and storage
            // (unsaved form drafts in localStorage, any Cache Storage; this also unregisters the
            // service worker: the page navigates to /login right after, which registers it again).
            'Clear-Site-Data': LOGOUT_CLEAR_SITE_DATA,
          },
        );
      },
    },
    {
      method: 'POST',
      path: '/api/elevate',
      role: 'public',
      changesState: true,
      bodyLimit: DEFAULT_BODY_LIMIT,
      audited: true,
      async handle(req, res, call) {
        const { address } = call;
        const w = who(req, true);
        if (w.mode === 'open') {
          sendJson(res, 400, { error: 'open mode: everyone already has every role' });
          return;
        }
        if (!w.session) {
          needLogin(res, w);
          return;
        }
        const onBehalfOf = w.session.user;
        const tablet = users.find(onBehalfOf);
        if (tablet?.role !== 'operator') {
          // Only an operator's tablet is unlocked: viewers send no commands, supervisors need no
          // PIN. Refused without looking at the PIN.
          const claimed = elevateSchema.safeParse(await call.body().catch(() => ({})));
          record({
            type: 'elevate-failed',
            result: 'refused',
            user: claimed.success ? claimed.data.name : onBehalfOf,
            onBehalfOf,
            source: 'gateway',
            address,
            role: 'operator',
            error: `only an operator's session can be unlocked (${onBehalfOf} is ${tablet?.role ?? 'gone'})`,
          });
          sendJson(res, 403, {
            error: 'a supervisor PIN unlocks only an operator’s tablet',
            needs: 'operator',
          });
          return;
        }
        const body = await readAttempt(res, call, elevateSchema, 'send { "name": …, "pin": … }');
        if (!body) return;
        const { name, pin } = body;
        const sup = await attempt(res, {
          type: 'elevate-failed',
          name,
          onBehalfOf,
          address,
          keys: pinKeys(name, onBehalfOf, address),
          limited: (key, retryAfterS) => pinRefusal(key, name, onBehalfOf, retryAfterS),
          async verify() {
            if (!PIN_RULE.test(pin))
              // Not evaluated, but counted like any wrong PIN.
              return {
                ok: false,
                error: 'a PIN has 6 to 12 digits: not checked',
                answer:
                  'wrong supervisor name or PIN (a PIN has 6 to 12 digits; a shorter one must be set again with npm run user -- pin)',
              };
            const found = users.find(name);
            const real = found?.role === 'supervisor' && found.pinHash ? found.pinHash : null;
            const ok = await checkSecret(pin, real ?? users.dummyHash('pin'));
            return found && real && ok
              ? { ok: true, owner: found }
              : { ok: false, error: 'wrong supervisor or PIN', answer: 'wrong supervisor name or PIN' };
          },
          failNote: () => pinLockNote(name, onBehalfOf, address),
        });
        if (!sup) return;
        unlocks.remember(sup.name, tabletOf(onBehalfOf, address));
        w.session.elevation = { supervisor: sup.name, until: now() + elevationMs };
        record({
          type: 'elevate',
          result: 'ok',
          user: sup.name,
          onBehalfOf,
          role: 'supervisor',
          source: 'gateway',
          address,
        });
        sendJson(res, 200, sessionBody(who(req, false)));
      },
    },
    {
      method: 'DELETE',
      path: '/api/elevate',
      role: 'public',
      changesState: true,
      audited: true,
      handle(req, res, call) {
        const { address } = call;
        const w = who(req, false);
        if (w.session?.elevation) {
          record({
            type: 'elevate-end',
            result: 'ok',
            user: w.session.elevation.supervisor,
            onBehalfOf: w.session.user,
            source: 'gateway',
            address,
          });
          w.session.elevation = null;
        }
        sendJson(res, w.session ? 200 : 401, sessionBody(who(req, false)));
      },
    },
  ];
}
