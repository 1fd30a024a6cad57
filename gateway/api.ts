import bcrypt from 'bcryptjs';
import { randomBytes } from 'node:crypto';
import { type IncomingMessage, type ServerResponse } from 'node:http';
import { z } from 'zod';
import { roleAtLeast } from '../src/fleet/types';
import { auditQueryFrom, toCsv } from './audit';
import { SESSION_COOKIE } from './auth';
import { discoverXtool } from './discovery';
import { clientAddress, parseCookies, readJson, sameOrigin, sendJson } from './http-util';
import { machineInfo } from './machines';
import { checkSecret } from './users';
import type { GatewayContext, Who } from './context';
import { envNumber } from './context';

/** What the browser reports about a command it sent to a simulated machine (src/app/boot.ts). */
const clientAuditSchema = z.object({
  machine: z.string().max(40),
  method: z.string().max(10).optional(),
  path: z.string().max(2000).optional(),
  commandId: z.string().max(100).optional(),
  command: z.string().max(100).optional(),
  label: z.string().max(200).optional(),
  status: z.number().int().min(0).max(999).optional(),
  ok: z.boolean().optional(),
  result: z.string().max(500).optional(),
  error: z.string().max(500).optional(),
});

const loginSchema = z.object({ name: z.string().min(1).max(64), password: z.string().min(1).max(1024) });
const elevateSchema = z.object({ name: z.string().min(1).max(64), pin: z.string().min(1).max(64) });

/** A hash of nothing in particular: compared against when the user does not exist (same timing). */
let dummyHash: string | null = null;
function dummy(): string {
  dummyHash ??= bcrypt.hashSync(randomBytes(16).toString('hex'), 10);
  return dummyHash;
}

export function createApi(ctx: GatewayContext) {
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
    scrub,
    who,
    sessionBody,
    cookie,
    mayUseMachine,
    needLogin,
  } = ctx;

  // ---------------------------------------------------------------- /api

  async function api(req: IncomingMessage, res: ServerResponse, url: URL): Promise<void> {
    const method = req.method ?? 'GET';
    const route = `${method} ${url.pathname}`;
    const address = clientAddress(req);
    if (method !== 'GET' && method !== 'HEAD' && !sameOrigin(req)) {
      sendJson(res, 403, { error: 'cross-site request refused' });
      return;
    }
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
        const keys = [`user:${name}`, `addr:${address}`];
        const wait = limiter.retryAfter(keys);
        if (wait > 0) {
          record({
            type: 'login-failed',
            result: 'refused',
            user: name,
            source: 'gateway',
            address,
            error: 'too many failed logins',
          });
          sendJson(
            res,
            429,
            { error: `too many failed logins: try again in ${wait} s`, retryAfterS: wait },
            { 'Retry-After': String(wait) },
          );
          return;
        }
        const u = users.find(name);
        const ok = await checkSecret(password, u?.passwordHash ?? dummy());
        if (!u || !ok) {
          limiter.fail(keys);
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
        limiter.reset(`user:${name}`);
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
        const body = elevateSchema.safeParse(await readJson(req));
        if (!body.success) {
          sendJson(res, 400, { error: 'send { "name": …, "pin": … }' });
          return;
        }
        const { name, pin } = body.data;
        const keys = [`pin:${name}`, `addr:${address}`];
        const wait = limiter.retryAfter(keys);
        const onBehalfOf = w.session.user;
        if (wait > 0) {
          record({
            type: 'elevate-failed',
            result: 'refused',
            user: name,
            onBehalfOf,
            source: 'gateway',
            address,
            error: 'too many failed PINs',
          });
          sendJson(
            res,
            429,
            { error: `too many failed PINs: try again in ${wait} s`, retryAfterS: wait },
            { 'Retry-After': String(wait) },
          );
          return;
        }
        const sup = users.find(name);
        const ok = await checkSecret(pin, sup?.pinHash ?? dummy());
        if (!sup || !ok || sup.role !== 'supervisor' || !sup.pinHash) {
          limiter.fail(keys);
          record({
            type: 'elevate-failed',
            result: 'failed',
            user: name,
            onBehalfOf,
            source: 'gateway',
            address,
            error: 'wrong supervisor or PIN',
          });
          sendJson(res, 401, { error: 'wrong supervisor name or PIN' });
          return;
        }
        limiter.reset(`pin:${name}`);
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
        const machines = config.machines.filter((m) => mayUseMachine(p, m.id)).map(machineInfo);
        // `demo`: the built-in demo fleet (no machines file): the console starts demo jobs.
        sendJson(res, 200, {
          machines,
          demo: config.file === null && config.machines.every((m) => m.simulated),
        });
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
        if (url.pathname.endsWith('.csv')) {
          const csv = toCsv(audit.filtered(q));
          res.writeHead(200, {
            'Content-Type': 'text/csv; charset=utf-8',
            'Content-Disposition': 'attachment; filename="shopdeck-audit.csv"',
            'Cache-Control': 'no-store',
          });
          res.end(csv);
        } else {
          sendJson(res, 200, audit.query(q));
        }
        return;
      }
      case 'POST /api/audit/client': {
        const w = who(req, true);
        if (!w.principal) {
          needLogin(res, w);
          return;
        }
        const body = clientAuditSchema.safeParse(await readJson(req));
        if (!body.success) {
          sendJson(res, 400, { error: 'not an audit record' });
          return;
        }
        const b = body.data;
        const m = byId.get(b.machine);
        if (!m || !m.simulated || !mayUseMachine(w.principal, m.id)) {
          sendJson(res, 403, { error: 'the browser may only record commands it sent to simulated machines' });
          return;
        }
        const ok = b.ok ?? (b.status !== undefined && b.status < 400);
        record({
          type: 'command',
          result: ok ? 'ok' : 'error',
          user: w.principal.name,
          onBehalfOf: w.principal.onBehalfOf,
          source: 'client',
          machine: m.id,
          method: b.method?.toUpperCase(),
          path: b.path === undefined ? undefined : scrub(b.path),
          commandId: b.commandId ?? b.command,
          label: b.label,
          status: b.status,
          detail: b.result === undefined ? undefined : scrub(b.result),
          error: b.error === undefined ? undefined : scrub(b.error),
          address,
        });
        sendJson(res, 201, { ok: true });
        return;
      }
      case 'GET /api/discover/xtool': {
        const w = who(req, false);
        if (!w.principal) {
          needLogin(res, w);
          return;
        }
        if (!roleAtLeast(w.principal.role, 'supervisor')) {
          sendJson(res, 403, {
            error: 'finding lasers on the network is for supervisors',
            needs: 'supervisor',
          });
          return;
        }
        const d = opts.discovery ?? {};
        const result = await discoverXtool({
          broadcast: d.broadcast ?? env.SHOPDECK_DISCOVERY_BROADCAST ?? '255.255.255.255',
          udpPort: d.udpPort ?? envNumber(env, 'SHOPDECK_DISCOVERY_UDP_PORT') ?? 20000,
          tcpPort: d.tcpPort ?? envNumber(env, 'SHOPDECK_DISCOVERY_TCP_PORT') ?? 20001,
          listenUdpPort: d.listenUdpPort,
          listenMs: d.listenMs ?? 2000,
          bindAddress: d.bindAddress,
        });
        sendJson(res, 200, result);
        return;
      }
      default:
        sendJson(res, 404, { error: `no such endpoint: ${method} ${url.pathname}` });
    }
  }

  return api;
}
