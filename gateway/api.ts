import { listPins, pinInfo } from './tls-pin';
import { type IncomingMessage, type ServerResponse } from 'node:http';
import { z } from 'zod';
import { mostSevereAlarm, roleAtLeast, type ServerWatch } from '../src/fleet/types';
import { auditQueryFrom, streamCsv } from './audit';
import { LoginHistory, SESSION_COOKIE, type LimitKey } from './auth';
import { clientAddress, parseCookies, readJson, sendJson } from './http-util';
import type { WatchJobRecord, WatchSummary } from '../src/fleet/contract';
import { machineInfo } from './machines';
import { LOGOUT_CLEAR_SITE_DATA } from './page-headers';
import { createSimApi, SIM_API_PATH } from './sim-api';
import { PIN_RULE, checkSecret } from './users';
import type { GatewayContext, Principal, Who } from './context';
import { type AlarmCentre, createAlarmStores, webhookPayload } from './alarms';
import type { SettingsStore } from './settings';
import type { Webhook } from './webhook';
import type { History } from './history';
import { createHistoryApi, HISTORY_API_PATH } from './history/api';
import { retentionSchema, shiftsSchema } from './settings';
import { createTemperaturesApi, TEMPERATURES_API_PATH, TemperatureStore } from './temperatures';

const loginSchema = z.object({ name: z.string().min(1).max(64), password: z.string().min(1).max(1024) });
const elevateSchema = z.object({ name: z.string().min(1).max(64), pin: z.string().min(1).max(64) });

function tooMany(res: ServerResponse, error: string, retryAfterS: number): void {
  sendJson(res, 429, { error, retryAfterS }, { 'Retry-After': String(retryAfterS) });
}

const ackSchema = z.union([
  z.object({ id: z.string().min(1).max(40) }).strict(),
  z.object({ machine: z.string().min(1).max(100), key: z.string().min(1).max(200) }).strict(),
]);
/** `PUT /api/settings`: any of the fields, at least one. */
const settingsSchema = z
  .object({
    alarmWebhook: z.string().trim().max(2000).nullable().optional(),
    shifts: shiftsSchema.optional(),
    retention: retentionSchema.optional(),
  })
  .strict()
  .refine((b) => Object.keys(b).length > 0, 'send at least one setting');
const ALARM_STATES = ['active', 'unacknowledged', 'cleared', 'all'] as const;
const SEVERITIES = ['critical', 'warning', 'info'] as const;

function oneOf<T extends string>(values: readonly T[], v: string | null): T | undefined {
  return values.find((x) => x === v);
}

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

/** A machine's watch summary as `GET /api/machines` gives it (the fleet page's first screen). */
export interface Watched {
  summary: WatchSummary;
  /** When the watch last heard the machine (ms, the gateway's clock); null: not yet. */
  lastSeen: number | null;
  /** The job the watch keeps a record of (watch.ts `nextJobRecord`); null or absent: none. */
  job?: WatchJobRecord | null;
}

/** Longest text of a controller's the machines list carries (a job name, an alarm). */
const WATCH_TEXT_MAX = 200;

/**
 * The summary sent with a machine (`watch`): state, job, progress and alarm as the gateway's watch
 * last read them, and how long ago (its age, not a clock time: the tablet's clock may differ).
 * Controller text is scrubbed of the machine's secrets and cut short; the page escapes it.
 */
export function watchForPage(
  w: Watched | null,
  now: number,
  scrub: (text: string) => string,
): ServerWatch | undefined {
  if (!w) return undefined;
  const s = w.summary;
  const { state } = s;
  const text = (t: string | null): string | null => (t === null ? null : scrub(t).slice(0, WATCH_TEXT_MAX));
  // Answered, but not readable by the server (a web page for a model): said so, its age kept.
  if (s.unread && state !== 'offline')
    return {
      state: 'unread',
      job: null,
      progress: null,
      alarm: null,
      alarmSeverity: null,
      unread: text(s.unread),
      ageMs: w.lastSeen === null ? null : Math.max(0, now - w.lastSeen),
    };
  if (state === 'unknown') return undefined;
  return {
    state,
    job: text(s.job),
    progress: typeof s.progress === 'number' && s.progress >= 0 && s.progress <= 1 ? s.progress : null,
    alarm: text(s.alarm),
    // The worst of the alarms the watch read (a warning when it did not say).
    alarmSeverity: s.alarm === null ? null : (mostSevereAlarm(s.alarms ?? [])?.severity ?? 'warning'),
    ageMs: w.lastSeen === null ? null : Math.max(0, now - w.lastSeen),
    // The job record, every view's job facts: its start as an age (the tablet's clock may differ).
    record: w.job
      ? {
          name: text(w.job.name),
          elapsedMs: Math.max(0, now - w.job.startedAt),
          startSeen: w.job.startSeen,
          progress: w.job.progress,
        }
      : null,
  };
}

export function createApi(ctx: GatewayContext, stores: ApiStores = createAlarmStores(ctx)) {
  const { alarms, settings, webhook, history } = stores;
  const historyApi = history ? createHistoryApi(ctx, history) : null;
  const {
    revalidateSockets,
    opts,
    env,
    now,
    config,
    users,
    audit,
    elevationMs,
    sessions,
    limiter,
    byId,
    record,
    who,
    sessionBody,
    cookie,
    mayUseMachine,
    needLogin,
    pins,
  } = ctx;
  const limits = limiter.opts;
  const simApi = createSimApi(ctx, stores.lookNow);
  const temperaturesApi = createTemperaturesApi(
    ctx,
    stores.temperatures ?? new TemperatureStore(now, ctx.scrub),
  );
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

  // ---------------------------------------------------------------- /api

  async function api(req: IncomingMessage, res: ServerResponse, url: URL): Promise<void> {
    const method = req.method ?? 'GET';
    const route = `${method} ${url.pathname}`;
    const address = clientAddress(req);
    // Cross-site requests were refused before this (gateway.ts, csrf.ts).
    switch (route) {
      case 'GET /api/session': {
        sendJson(res, 200, sessionBody(who(req, false)));
        return;
      }
      case 'POST /api/session/activity': {
        const w = who(req, true);
        sendJson(res, w.principal ? 200 : 401, sessionBody(w));
        return;
      }
      case 'POST /api/login': {
        if (users.mode === 'open') {
          sendJson(res, 400, { error: 'open mode: there are no users to log in as' });
          return;
        }
        const body = loginSchema.safeParse(await readJson(req));
        if (!body.success) {
          sendJson(res, 400, { error: 'send { "name": …, "password": … }' });
          return;
        }
        const { name, password } = body.data;
        // Counted BEFORE the slow comparison: concurrent guesses cannot all pass the check.
        const keys = loginKeys(name, address);
        const slot = limiter.reserve(keys);
        if (!slot.ok) {
          record({
            type: 'login-failed',
            result: 'refused',
            user: name,
            source: 'gateway',
            address,
            error: slot.key.startsWith('user:')
              ? 'too many failed logins for this user from addresses it never logged in from'
              : 'too many failed logins',
          });
          tooMany(res, `too many failed logins: try again in ${slot.retryAfterS} s`, slot.retryAfterS);
          return;
        }
        const u = users.find(name);
        const ok = await checkSecret(password, u?.passwordHash ?? users.dummyHash('password'));
        if (!u || !ok) {
          record({
            type: 'login-failed',
            result: 'failed',
            user: name,
            source: 'gateway',
            address,
            error: 'wrong name or password',
          });
          sendJson(res, 401, { error: 'wrong name or password' });
          return;
        }
        slot.release();
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
        return;
      }
      case 'POST /api/logout': {
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
        return;
      }
      case 'POST /api/elevate': {
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
          const claimed = elevateSchema.safeParse(await readJson(req).catch(() => ({})));
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
        const body = elevateSchema.safeParse(await readJson(req));
        if (!body.success) {
          sendJson(res, 400, { error: 'send { "name": …, "pin": … }' });
          return;
        }
        const { name, pin } = body.data;
        // Counted BEFORE the slow comparison: concurrent guesses cannot all pass the check.
        const slot = limiter.reserve(pinKeys(name, onBehalfOf, address));
        if (!slot.ok) {
          const [error, answer] = pinRefusal(slot.key, name, onBehalfOf, slot.retryAfterS);
          record({
            type: 'elevate-failed',
            result: 'refused',
            user: name,
            onBehalfOf,
            source: 'gateway',
            address,
            error,
          });
          tooMany(res, answer, slot.retryAfterS);
          return;
        }
        const fail = (error: string, answer: string): void => {
          record({
            type: 'elevate-failed',
            result: 'failed',
            user: name,
            onBehalfOf,
            source: 'gateway',
            address,
            error: error + pinLockNote(name, onBehalfOf, address),
          });
          sendJson(res, 401, { error: answer });
        };
        if (!PIN_RULE.test(pin)) {
          // Not evaluated, but counted like any wrong PIN.
          fail(
            'a PIN has 6 to 12 digits: not checked',
            'wrong supervisor name or PIN (a PIN has 6 to 12 digits; a shorter one must be set again with npm run user -- pin)',
          );
          return;
        }
        const sup = users.find(name);
        const real = sup?.role === 'supervisor' && sup.pinHash ? sup.pinHash : null;
        const ok = await checkSecret(pin, real ?? users.dummyHash('pin'));
        if (!sup || !real || !ok) {
          fail('wrong supervisor or PIN', 'wrong supervisor name or PIN');
          return;
        }
        slot.release();
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
        return;
      }
      case 'DELETE /api/elevate': {
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
        return;
      }
      case 'GET /api/machines': {
        const w = who(req, false);
        if (!w.principal) {
          needLogin(res, w);
          return;
        }
        const p = w.principal;
        const t = now();
        const machines = config.machines
          .filter((m) => mayUseMachine(p, m.id))
          .map((m) => {
            const watch = watchForPage(stores.watched?.(m.id) ?? null, t, ctx.scrub);
            return watch ? { ...machineInfo(m), watch } : machineInfo(m);
          });
        // `demo`: the built-in demo fleet (no machines file): the gateway runs demo jobs.
        sendJson(res, 200, { machines, demo: ctx.builtInDemo });
        return;
      }
      case 'GET /api/audit':
      case 'GET /api/audit.csv': {
        const w = who(req, false);
        if (!w.principal) {
          needLogin(res, w);
          return;
        }
        if (!roleAtLeast(w.principal.role, 'supervisor')) {
          sendJson(res, 403, { error: 'the audit log is for supervisors', needs: 'supervisor' });
          return;
        }
        const q = { ...auditQueryFrom(url.searchParams), machines: w.principal.machines };
        try {
          if (url.pathname.endsWith('.csv')) await streamCsv(audit, q, res);
          else sendJson(res, 200, await audit.query(q));
        } catch (e) {
          if (res.headersSent) res.destroy();
          else
            sendJson(res, 503, {
              error: `the audit log cannot be read: ${ctx.scrub(e instanceof Error ? e.message : String(e))}`,
            });
        }
        return;
      }
      case 'GET /api/alarms': {
        const w = who(req, false);
        if (!w.principal) {
          needLogin(res, w);
          return;
        }
        const p = url.searchParams;
        // A page that already has this version is told so, not sent the list again.
        if (p.get('since') === String(alarms.version)) {
          sendJson(res, 200, { version: alarms.version, unchanged: true });
          return;
        }
        const limit = Number(p.get('limit'));
        const list = alarms.query({
          machines: w.principal.machines,
          machine: p.get('machine') || undefined,
          family: p.get('family') || undefined,
          severity: oneOf(SEVERITIES, p.get('severity')),
          state: oneOf(ALARM_STATES, p.get('state')),
          limit: Number.isInteger(limit) && limit > 0 ? Math.min(limit, 2000) : 500,
        });
        sendJson(res, 200, { version: alarms.version, alarms: list });
        return;
      }
      case 'POST /api/alarms/ack': {
        const w = who(req, true);
        if (!w.principal) {
          needLogin(res, w);
          return;
        }
        const pr = w.principal;
        const body = ackSchema.safeParse(await readJson(req));
        if (!body.success) {
          sendJson(res, 400, { error: 'send {"id": …} or {"machine": …, "key": …}' });
          return;
        }
        const b = body.data;
        // Only a record the alarm centre has: by id, or the open record of a machine's key. Never
        // in advance (an alarm that has not happened), never an invented key: 404, nothing kept.
        const target = 'id' in b ? alarms.get(b.id) : alarms.open(b.machine, b.key);
        const machineId = target?.machine;
        if (!target || !machineId || !mayUseMachine(pr, machineId)) {
          sendJson(res, 404, { error: 'no such alarm' });
          return;
        }
        if (!roleAtLeast(pr.role, 'operator')) {
          record({
            type: 'refused',
            result: 'refused',
            user: pr.name,
            source: 'gateway',
            machine: machineId,
            label: 'acknowledge alarm',
            role: 'operator',
            address,
            error: 'acknowledging an alarm needs an operator',
          });
          sendJson(res, 403, { error: 'acknowledging an alarm needs an operator', needs: 'operator' });
          return;
        }
        const by = pr.onBehalfOf ? `${pr.name} (on ${pr.onBehalfOf}'s tablet)` : pr.name;
        const out = alarms.acknowledge(target.id, by);
        if (out === 'already' || out === null) {
          sendJson(res, 200, { alarm: target, already: true });
          return;
        }
        const r = out;
        record({
          type: 'alarm-ack',
          result: 'ok',
          user: pr.name,
          onBehalfOf: pr.onBehalfOf,
          source: 'gateway',
          machine: machineId,
          address,
          detail: `acknowledged: ${r.text}`.slice(0, 500),
        });
        sendJson(res, 200, { alarm: r });
        return;
      }
      case 'GET /api/settings': {
        if (!supervisorOnly(req, res, 'the server settings are for supervisors')) return;
        sendJson(res, 200, {
          ...settings.view(),
          webhook: { ...webhook.stats, waiting: webhook.waiting },
          // The history database's size on disk (bytes), null when it could not be opened.
          historyBytes: history?.store?.sizeBytes() ?? null,
        });
        return;
      }
      case 'PUT /api/settings': {
        const p = supervisorOnly(req, res, 'the server settings are for supervisors');
        if (!p) return;
        const body = settingsSchema.safeParse(await readJson(req));
        if (!body.success) {
          const i = body.error.issues[0];
          const where = i?.path.length ? `${i.path.join('.')}: ` : '';
          sendJson(res, 400, {
            error: `send {"alarmWebhook": "https://…" or null, "shifts": [{"name", "start": "HH:MM", "end": "HH:MM"}], "retention": {"jobsDays", "statesDays"}}, any of them (${where}${i?.message ?? 'invalid'})`,
          });
          return;
        }
        const b = body.data;
        const said: string[] = [];
        if (b.alarmWebhook !== undefined) {
          const url = b.alarmWebhook || null;
          const problem = settings.setWebhook(url);
          if (problem) {
            sendJson(res, 400, { error: problem });
            return;
          }
          said.push(
            url
              ? `alarm webhook set to ${settings.view().alarmWebhook.shown ?? ''}`
              : 'alarm webhook removed',
          );
        }
        if (b.shifts || b.retention) {
          const problem = settings.setHistory({ shifts: b.shifts, retention: b.retention });
          if (problem) {
            sendJson(res, 400, { error: problem });
            return;
          }
          if (b.shifts)
            said.push(`shifts: ${b.shifts.map((s) => `${s.name} ${s.start}–${s.end}`).join(', ') || 'none'}`);
          if (b.retention) {
            said.push(
              `history kept: jobs ${b.retention.jobsDays} days, state changes ${b.retention.statesDays} days`,
            );
            history?.prune();
          }
        }
        const view = settings.view();
        record({
          type: 'settings',
          result: 'ok',
          user: p.name,
          onBehalfOf: p.onBehalfOf,
          source: 'gateway',
          address,
          detail: said.join('; ').slice(0, 1000),
        });
        sendJson(res, 200, view);
        return;
      }
      case 'POST /api/settings/test-webhook': {
        const p = supervisorOnly(req, res, 'the server settings are for supervisors');
        if (!p) return;
        const t = now();
        const result = await webhook.tryOnce(
          webhookPayload('test', {
            id: 'test',
            machine: 'test',
            machineName: 'Shopdeck',
            family: 'test',
            key: 'test',
            severity: 'info',
            blocking: false,
            text: `a test sent by ${p.name} from the console's settings`,
            since: t,
            clearedAt: null,
            ackBy: null,
            ackAt: null,
          }),
        );
        // Only whether it was delivered: the reason (refused, not HTTP, the receiver's status)
        // would make this a port scanner of the shop network. The server's log says why.
        sendJson(res, 200, result.ok ? { ok: true, result: 'delivered' } : { ok: false, result: 'failed' });
        return;
      }
      case 'GET /api/tls': {
        const p = supervisorOnly(req, res, 'the controllers’ certificates are for supervisors');
        if (!p) return;
        try {
          sendJson(res, 200, {
            machines: listPins(
              config.machines.filter((m) => mayUseMachine(p, m.id)),
              pins,
            ),
          });
        } catch (e) {
          sendJson(res, 500, { error: e instanceof Error ? e.message : String(e) });
        }
        return;
      }
      default: {
        if (historyApi && HISTORY_API_PATH.test(url.pathname)) {
          await historyApi(req, res, url);
          return;
        }
        const temps = TEMPERATURES_API_PATH.exec(url.pathname);
        if (temps) {
          temperaturesApi(req, res, url, temps[1] ?? '');
          return;
        }
        const sim = SIM_API_PATH.exec(url.pathname);
        if (sim) {
          await simApi(req, res, sim[1] ?? '');
          return;
        }
        const forget = /^\/api\/tls\/([a-z0-9-]{1,40})$/.exec(url.pathname);
        if (method === 'DELETE' && forget) {
          const p = supervisorOnly(req, res, 'accepting a new certificate is for supervisors');
          if (!p) return;
          const m = byId.get(forget[1] ?? '');
          const view = m && mayUseMachine(p, m.id) ? pinInfo(m, pins) : null;
          if (!m || !view) {
            sendJson(res, 404, { error: 'no machine reached over TLS by that id' });
            return;
          }
          if (!view.canForget) {
            sendJson(res, 409, {
              error:
                view.mode === 'configured'
                  ? 'its fingerprint is in the machines file (tlsFingerprint): change it there'
                  : 'no certificate is pinned for it yet',
            });
            return;
          }
          const gone = pins.forget(m.id);
          record({
            type: 'tls-forget',
            result: 'ok',
            user: p.name,
            onBehalfOf: p.onBehalfOf,
            source: 'gateway',
            machine: m.id,
            address,
            detail: `forgot the pinned certificate ${gone?.fingerprint ?? ''}: the next connection trusts what it is shown`,
          });
          sendJson(res, 200, { forgotten: gone });
          return;
        }
        // A family's own routes (its server part's `routes`): `GET /api/<name>/<kind>`.
        const own = /^\/api\/([a-z0-9-]{1,40})\/([a-z0-9-]{1,40})$/.exec(url.pathname);
        const famRoute =
          method === 'GET' && own
            ? Object.values(opts.families)
                .find((f) => f?.kind === own[2])
                ?.server?.routes?.find((r) => r.name === own[1])
            : undefined;
        if (famRoute) {
          const w = who(req, false);
          if (!w.principal) {
            needLogin(res, w);
            return;
          }
          if (!roleAtLeast(w.principal.role, famRoute.role)) {
            sendJson(res, 403, { error: famRoute.forbidden, needs: famRoute.role });
            return;
          }
          const answer = await famRoute.handle({ env, discovery: opts.discovery ?? {} });
          sendJson(res, answer.status, answer.body);
          return;
        }
        sendJson(res, 404, { error: `no such endpoint: ${method} ${url.pathname}` });
      }
    }
  }

  /** The principal when it is a supervisor (everyone in open mode); otherwise answers and null. */
  function supervisorOnly(req: IncomingMessage, res: ServerResponse, refusal: string): Principal | null {
    const w = who(req, false);
    if (!w.principal) {
      needLogin(res, w);
      return null;
    }
    if (!roleAtLeast(w.principal.role, 'supervisor')) {
      sendJson(res, 403, { error: refusal, needs: 'supervisor' });
      return null;
    }
    return w.principal;
  }

  return api;
}
