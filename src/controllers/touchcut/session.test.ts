import { http, HttpResponse } from 'msw';
import { setupServer } from 'msw/node';
import { afterAll, afterEach, beforeAll, beforeEach, describe, expect, it, vi } from 'vitest';
import { createContext } from '../../fleet/fleet';
import { alwaysVisible } from '../../fleet/link';
import { simulatorHandlers } from '../../fleet/msw';
import type { SessionContext } from '../../fleet/contract';
import { touchcutGateway } from './family';
import { TouchcutSession } from './session';
import { SIM_MONITOR_API_KEY, TouchcutSimulator } from './sim/simulator';
import { viaGateway, type GatewayStandIn } from './testkit';

let sim: TouchcutSimulator;
let gw: GatewayStandIn;
let ctx: SessionContext;
let session: TouchcutSession;
const server = setupServer();

beforeAll(() => server.listen({ onUnhandledRequest: 'error' }));
afterAll(() => server.close());

function setup(apiKey: string | undefined, role: 'viewer' | 'operator' | 'supervisor' = 'operator') {
  sim = new TouchcutSimulator({ id: 'tc', name: 'Plasma', tickMs: 100 });
  sim.autoOperator = false;
  gw = viaGateway(sim, apiKey);
  server.resetHandlers(...simulatorHandlers('tc', gw));
  ctx = createContext(
    { id: 'tc', name: 'Plasma', kind: 'touchcut', simulated: true },
    { visibility: alwaysVisible, now: () => Date.now(), principal: () => ({ name: 'sam', role }) },
  );
  session = new TouchcutSession(ctx);
}

async function settle(ms: number) {
  await vi.advanceTimersByTimeAsync(ms);
}

beforeEach(() => {
  vi.useFakeTimers({ toFake: ['setTimeout', 'clearTimeout', 'setInterval', 'clearInterval', 'Date'] });
});
afterEach(() => {
  session.stop();
  sim.dispose();
  vi.useRealTimers();
});

describe('touchcut session through msw', () => {
  it('goes online with the gateway key and fills the snapshot from status and machine-info', async () => {
    setup(SIM_MONITOR_API_KEY);
    session.start();
    await settle(1500);
    const snap = ctx.snapshot.getState();
    expect(snap.link).toBe('online');
    expect(snap.identity).toMatch(/TouchCut7 7\.0\.123/);
    expect(snap.activity).toBe('idle');
    expect(session.store.getState().status?.machineState).toBe('Idle');

    sim.startProgram();
    await settle(20_000);
    const running = ctx.snapshot.getState();
    expect(running.activity).toBe('running');
    expect(running.job?.name).toMatch(/\.nc$/);
    expect(running.job?.progress ?? 0).toBeGreaterThan(0);
    expect(running.positions.X).toBeGreaterThan(0);
    expect(running.job?.elapsed ?? 0).toBeGreaterThan(10);

    sim.fault();
    await settle(1500);
    const faulted = ctx.snapshot.getState();
    expect(faulted.activity).toBe('error');
    expect(faulted.alarms).toHaveLength(1);
    expect(faulted.alarms[0]?.severity).toBe('critical');
    expect(faulted.alarms[0]?.message).toBe('Torch collision detected');
    expect(ctx.log.store.getState().entries.some((e) => e.text === 'Torch collision detected')).toBe(true);
  });

  it('without a key it needs a login; a login brings it online; JWT expiry → needs login → login again', async () => {
    setup(undefined);
    session.start();
    await settle(1500);
    expect(ctx.snapshot.getState().link).toBe('needs-login');
    expect(session.store.getState().auth.reason).toMatch(/no accepted API key/);
    // The key is the gateway's: it is tried again on its own, slowly (faults.test.ts has the backoff).
    const before = gw.fromBrowser.length;
    await settle(10_000);
    const retried =
      gw.fromBrowser.filter((r) => r.path.includes('/status')).length -
      gw.fromBrowser.slice(0, before).filter((r) => r.path.includes('/status')).length;
    expect(retried).toBeGreaterThanOrEqual(1);
    expect(retried).toBeLessThanOrEqual(3);

    sim.jwtTtlMs = 20_000;
    await session.login({ username: 'operator', password: 'operator' });
    await settle(1500);
    expect(ctx.snapshot.getState().link).toBe('online');
    expect(session.store.getState().auth).toMatchObject({ mode: 'user', user: 'operator' });
    expect(session.store.getState().auth.expiresAt).toBeGreaterThan(Date.now());

    await settle(20_000);
    expect(ctx.snapshot.getState().link).toBe('needs-login');
    expect(session.store.getState().auth.reason).toMatch(/login of operator expired/);
    expect(session.loggedIn).toBe(false);

    await session.login({ username: 'operator', password: 'operator' });
    await settle(1500);
    expect(ctx.snapshot.getState().link).toBe('online');
  });

  it('a failed login keeps needs-login and explains; "not ready" is a notice, not an error', async () => {
    setup(undefined);
    session.start();
    await settle(1500);
    await expect(session.login({ username: 'operator', password: 'nope' })).rejects.toThrow(
      'Wrong TouchCut password',
    );
    expect(ctx.snapshot.getState().link).toBe('needs-login');
    sim.restartApp();
    await expect(session.login({ username: 'operator', password: 'operator' })).rejects.toThrow(/not ready/);
    expect(session.store.getState().notice).toMatch(/still starting/);
    expect(ctx.snapshot.getState().link).toBe('needs-login');
  });

  it('the API key never reaches the browser', async () => {
    setup(SIM_MONITOR_API_KEY);
    session.start();
    await settle(1500);
    const release = session.monitor.acquire();
    session.monitor.setFields(['axes.*', 'io.din']);
    const unsub = session.screenshot.subscribe();
    await settle(3000);
    release();
    unsub();
    expect(ctx.snapshot.getState().link).toBe('online');
    // The key was used between gateway and controller…
    expect(sim.requests.some((r) => r.headers['x-touchcut-api-key'] === SIM_MONITOR_API_KEY)).toBe(true);
    // …but nothing the browser sent or holds contains it.
    expect(gw.fromBrowser.length).toBeGreaterThan(3);
    for (const r of gw.fromBrowser) {
      expect(r.headers['x-touchcut-api-key']).toBeUndefined();
      expect(r.path).not.toContain(SIM_MONITOR_API_KEY);
    }
    const held = JSON.stringify([
      ctx.snapshot.getState(),
      session.store.getState(),
      session.monitor.store.getState(),
      ctx.log.store.getState(),
    ]);
    expect(held).not.toContain(SIM_MONITOR_API_KEY);
  });

  it('change password is a declared operator command that needs a user login', async () => {
    setup(SIM_MONITOR_API_KEY, 'operator');
    session.start();
    await settle(1500);
    const cmd = session.changePassword;
    expect(cmd.id).toBe('touchcut.changePassword');
    expect(ctx.commands.blockedReason(cmd)).toMatch(/user login/);
    await session.login({ username: 'admin', password: 'admin' });
    await settle(1500);
    expect(ctx.commands.blockedReason(cmd)).toBeNull();
    await ctx.commands.run(cmd, { oldPassword: 'admin', newPassword: 'n3w', confirmPassword: 'n3w' });
    expect(gw.fromBrowser.at(-1)?.headers['x-shopdeck-command']).toBe('touchcut.changePassword');
    expect(sim.users.find((u) => u.username === 'admin')?.password).toBe('n3w');
    await settle(1500);
    expect(ctx.snapshot.getState().link).toBe('online');
  });
});

describe('touchcut session: the gateway holds the user login', () => {
  /** Everything this browser holds about the machine, as text. */
  function heldByBrowser(): string {
    return JSON.stringify([
      ctx.snapshot.getState(),
      session.store.getState(),
      session.monitor.store.getState(),
      ctx.log.store.getState(),
      gw.toBrowser,
    ]);
  }

  it('a login shows the user and the expiry; the token never reaches the browser; logout ends it', async () => {
    setup(undefined);
    session.start();
    await settle(1500);
    expect(ctx.snapshot.getState().link).toBe('needs-login');
    const at = Date.now();
    await session.login({ username: 'operator', password: 'operator' });
    await settle(1500);
    expect(ctx.snapshot.getState().link).toBe('online');
    const token = gw.heldToken;
    expect(token).toMatch(/\./);
    const auth = session.store.getState().auth;
    expect(auth).toMatchObject({ mode: 'user', user: 'operator', reason: null });
    // The JWT's expiry (whole seconds), read by the gateway.
    expect(auth.expiresAt).toBeGreaterThan(at + sim.jwtTtlMs - 1001);
    expect(auth.expiresAt).toBeLessThanOrEqual(at + sim.jwtTtlMs);
    // The controller got the gateway's JWT; the browser sent none and holds none.
    expect(sim.requests.at(-1)?.headers.authorization).toBe(`Bearer ${token}`);
    for (const r of gw.fromBrowser) expect(r.headers.authorization).toBeUndefined();
    expect(heldByBrowser()).not.toContain(token);
    expect(heldByBrowser()).not.toContain('"password"');

    await session.logout();
    expect(gw.heldToken).toBeNull();
    expect(session.store.getState().auth).toMatchObject({ mode: 'key', user: null });
    expect(
      ctx.log.store.getState().entries.some((e) => /logged out of TouchCut \(operator\)/.test(e.text)),
    ).toBe(true);
    // Without a login and without a key: TouchCut says 401, the machine needs a login again.
    await settle(1500);
    expect(ctx.snapshot.getState().link).toBe('needs-login');
    expect(session.store.getState().auth.reason).toMatch(/no accepted API key/);
  });

  it('a 401 after login (the login was revoked) → needs login; "try again without a login" uses the key', async () => {
    setup(SIM_MONITOR_API_KEY);
    session.start();
    await session.login({ username: 'admin', password: 'admin' });
    await settle(1500);
    expect(ctx.snapshot.getState().link).toBe('online');
    sim.expireAllTokens();
    await settle(1500);
    expect(ctx.snapshot.getState().link).toBe('needs-login');
    expect(session.store.getState().auth).toMatchObject({ mode: 'key', user: null });
    expect(session.store.getState().auth.reason).toMatch(/login of admin expired or was revoked/);
    // The gateway forgot the JWT on that 401: nothing is asked of the controller meanwhile.
    expect(gw.heldToken).toBeNull();
    const asked = sim.requests.length;
    await settle(5000);
    expect(sim.requests.filter((r) => r.path.includes('/status')).length).toBe(
      sim.requests.slice(0, asked).filter((r) => r.path.includes('/status')).length,
    );
    session.retryWithoutLogin();
    await settle(1500);
    expect(ctx.snapshot.getState().link).toBe('online');
    expect(sim.requests.at(-1)?.headers['x-touchcut-api-key']).toBe(SIM_MONITOR_API_KEY);
  });

  it('a second browser shares the login: it shows the user and leaves "needs login" without logging in', async () => {
    setup(undefined);
    session.start();
    await settle(1500);
    const other = new TouchcutSession(
      createContext(
        { id: 'tc', name: 'Plasma', kind: 'touchcut', simulated: true },
        {
          visibility: alwaysVisible,
          now: () => Date.now(),
          principal: () => ({ name: 'vic', role: 'viewer' }),
        },
      ),
    );
    other.start();
    await settle(1500);
    expect(other.ctx.snapshot.getState().link).toBe('needs-login');
    await session.login({ username: 'operator', password: 'operator' });
    const logins = sim.requests.filter((r) => r.path.startsWith('/rest/v1/auth')).length;
    await settle(16_000);
    expect(other.store.getState().auth).toMatchObject({ mode: 'user', user: 'operator' });
    expect(other.ctx.snapshot.getState().link).toBe('online');
    // One login upstream for both.
    expect(sim.requests.filter((r) => r.path.startsWith('/rest/v1/auth')).length).toBe(logins);
    // The first browser logs out: the second one sees it at its next look.
    await session.logout();
    await settle(16_000);
    expect(other.store.getState().auth.mode).toBe('key');
    other.stop();
  });
});

describe('touchcut session: application not ready', () => {
  it('a status answer "100 Application not ready" is a notice and a quick retry, not an error', async () => {
    setup(SIM_MONITOR_API_KEY);
    let starting = true;
    server.use(
      http.get('http://shopdeck.test/machines/tc/rest/v1/status', () =>
        starting
          ? HttpResponse.json({ code: '100', msg: 'Application not ready' }, { status: 400 })
          : undefined,
      ),
    );
    session.start();
    await settle(1500);
    expect(ctx.snapshot.getState().link).toBe('connecting');
    expect(ctx.snapshot.getState().problem).toBeNull();
    expect(session.store.getState().notice).toMatch(/still starting/);
    starting = false;
    await settle(2500);
    expect(ctx.snapshot.getState().link).toBe('online');
    expect(session.store.getState().notice).toBeNull();
  });
});

describe('touchcut gateway hint', () => {
  it('adds the key as a header only when no user is logged in, and drops a key sent by the browser', () => {
    const q = new URLSearchParams('units=metric');
    const h1: Record<string, string> = { 'x-touchcut-api-key': 'from-browser' };
    touchcutGateway.injectSecrets?.(
      { method: 'GET', path: '/rest/v1/status', headers: h1, query: q },
      { apiKey: 'K' },
    );
    expect(h1).toEqual({ 'X-TouchCut-API-Key': 'K' });
    expect(q.toString()).toBe('units=metric');

    const h2: Record<string, string> = { Authorization: 'Bearer a.b.c' };
    touchcutGateway.injectSecrets?.(
      { method: 'GET', path: '/rest/v1/status', headers: h2, query: q },
      { apiKey: 'K' },
    );
    expect(h2).toEqual({ Authorization: 'Bearer a.b.c' });

    const h4: Record<string, string> = {};
    touchcutGateway.injectSecrets?.(
      { method: 'POST', path: '/rest/v1/auth', headers: h4, query: q },
      { apiKey: 'K' },
    );
    touchcutGateway.injectSecrets?.(
      { method: 'GET', path: '/rest/v1/machine-info', headers: h4, query: q },
      { apiKey: 'K' },
    );
    expect(h4).toEqual({});

    const h3: Record<string, string> = {};
    touchcutGateway.injectSecrets?.({ method: 'GET', path: '/rest/v1/status', headers: h3, query: q }, {});
    expect(h3).toEqual({});
  });
});
