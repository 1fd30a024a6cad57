import { setupServer } from 'msw/node';
import { afterAll, afterEach, beforeAll, describe, expect, it } from 'vitest';
import { LinkError } from '../../fleet/errors';
import { simulatorHandlers } from '../../fleet/msw';
import { isNotReady, parseTouchcutError, TouchcutClient } from './client';
import { SIM_MONITOR_API_KEY, TouchcutSimulator } from './sim/simulator';
import { viaGateway } from './testkit';

const sim = new TouchcutSimulator({ id: 'tc', name: 'Plasma' });
const gw = viaGateway(sim, SIM_MONITOR_API_KEY);
const server = setupServer(...simulatorHandlers('tc', gw));
beforeAll(() => server.listen({ onUnhandledRequest: 'error' }));
afterAll(() => {
  server.close();
  sim.dispose();
});
afterEach(async () => {
  sim.notReadyUntil = 0;
  sim.breakJwt = false;
  gw.apiKey = SIM_MONITOR_API_KEY;
  // The login is the gateway's, shared: each test starts without one.
  await new TouchcutClient('tc').logout();
});

async function failure(p: Promise<unknown>): Promise<LinkError> {
  try {
    await p;
  } catch (e) {
    expect(e).toBeInstanceOf(LinkError);
    return e as LinkError;
  }
  throw new Error('expected a failure');
}

describe('touchcut client: auth error paths (manual "Failure Responses")', () => {
  it('1003 missing username / password', async () => {
    const c = new TouchcutClient('tc');
    const a = await failure(c.login('', 'x'));
    expect(a.vendorCode).toBe('1003');
    expect(a.status).toBe(400);
    expect(a.message).toMatch(/required parameter is missing/);
    expect(a.message).toMatch(/username/);
    const b = await failure(c.login('operator', ''));
    expect(b.vendorCode).toBe('1003');
    expect(b.message).toMatch(/password/);
  });

  it('101 invalid username and 102 invalid password', async () => {
    const c = new TouchcutClient('tc');
    expect((await failure(c.login('nobody', 'x'))).message).toBe('TouchCut does not know this user name');
    expect((await failure(c.login('operator', 'wrong'))).message).toBe('Wrong TouchCut password');
    expect(gw.heldToken).toBeNull();
  });

  it('100 application not ready is recognisable as "retry later"', async () => {
    sim.restartApp();
    const e = await failure(new TouchcutClient('tc').login('operator', 'operator'));
    expect(isNotReady(e)).toBe(true);
    expect(e.message).toMatch(/try again in a moment/);
  });

  it('2000 could not create token', async () => {
    sim.breakJwt = true;
    const e = await failure(new TouchcutClient('tc').login('operator', 'operator'));
    expect(e.status).toBe(500);
    expect(e.vendorCode).toBe('2000');
    expect(e.message).toMatch(/could not create a login token/);
  });

  it('401 for a user without web access', async () => {
    const e = await failure(new TouchcutClient('tc').login('guest', 'guest'));
    expect(e.status).toBe(401);
    expect(e.message).toMatch(/web access/);
  });

  it('logs in through the gateway: the browser gets the user and expiry, never the JWT', async () => {
    const c = new TouchcutClient('tc');
    const held = await c.login('operator', 'operator');
    expect(held).toMatchObject({ loggedIn: true, user: 'operator', success: true });
    expect(held.expiresAt).toBeGreaterThan(Date.now());
    const token = gw.heldToken;
    expect(token).toMatch(/^\S+\.\S+\.\S+$/);
    expect(JSON.stringify(held)).not.toContain(token);
    expect(gw.toBrowser.join('\n')).not.toContain(token);
    await c.status();
    // The browser sent no token; the gateway added its own, and no key on top of a user login.
    expect(gw.fromBrowser.at(-1)?.headers.authorization).toBeUndefined();
    expect(sim.requests.at(-1)?.headers.authorization).toBe(`Bearer ${token}`);
    expect(sim.requests.at(-1)?.headers['x-touchcut-api-key']).toBeUndefined();
    // Another browser (a new client) reads the same login; a logout ends it for both.
    expect(await new TouchcutClient('tc').loginState()).toMatchObject({ loggedIn: true, user: 'operator' });
    await new TouchcutClient('tc').logout();
    expect(gw.heldToken).toBeNull();
    expect(await c.loginState()).toMatchObject({ loggedIn: false });
    await c.status();
    expect(sim.requests.at(-1)?.headers['x-touchcut-api-key']).toBe(SIM_MONITOR_API_KEY);
  });
});

describe('touchcut client: change-password error paths', () => {
  it('without a user login TouchCut refuses it (an API key cannot change a password)', async () => {
    const e = await failure(
      new TouchcutClient('tc').changePassword(
        { oldPassword: 'a', newPassword: 'b', confirmPassword: 'b' },
        'x',
      ),
    );
    expect(e.status).toBe(401);
  });

  it('the simulator answers 401 to change-password with only an API key', async () => {
    const r = await fetch('http://shopdeck.test/machines/tc/rest/v1/auth/change-password', {
      method: 'POST',
      body: new URLSearchParams({ 'old-password': 'a', 'new-password': 'b', 'confirm-password': 'b' }),
    });
    expect(r.status).toBe(401);
  });

  it('1003 for each missing parameter, 1002 on mismatch, 102 on a wrong old password', async () => {
    const c = new TouchcutClient('tc');
    await c.login('admin', 'admin');
    const p = (oldPassword: string, newPassword: string, confirmPassword: string) =>
      failure(c.changePassword({ oldPassword, newPassword, confirmPassword }, 'touchcut.changePassword'));
    expect((await p('', 'n', 'n')).vendorMessage).toMatch(/old-password/);
    expect((await p('admin', '', 'n')).vendorMessage).toMatch(/new-password/);
    expect((await p('admin', 'n', '')).vendorMessage).toMatch(/confirm-password/);
    const mismatch = await p('admin', 'n1', 'n2');
    expect(mismatch.vendorCode).toBe('1002');
    expect(mismatch.message).toMatch(/do not match/);
    expect((await p('nope', 'n', 'n')).vendorCode).toBe('102');
  });

  it('403 names the privilege; 101 when the user is gone; success returns a new JWT and carries the command id', async () => {
    const v = new TouchcutClient('tc');
    await v.login('viewer', 'viewer');
    const forbidden = await failure(
      v.changePassword({ oldPassword: 'viewer', newPassword: 'n', confirmPassword: 'n' }, 'c'),
    );
    expect(forbidden.status).toBe(403);
    expect(forbidden.message).toMatch(/Modify Current User/);

    const o = new TouchcutClient('tc');
    await o.login('office', 'office');
    const before = sim.tokens.size;
    const old = gw.heldToken;
    const changed = await o.changePassword(
      { oldPassword: 'office', newPassword: 'office2', confirmPassword: 'office2' },
      'touchcut.changePassword',
    );
    expect(sim.tokens.size).toBe(before + 1);
    // The new JWT is the gateway's: the answer has the user and expiry only.
    expect(gw.heldToken).not.toBe(old);
    expect(changed).toMatchObject({ loggedIn: true, user: 'office' });
    expect(JSON.stringify(changed)).not.toContain(gw.heldToken ?? '-');
    expect(gw.fromBrowser.at(-1)?.headers['x-shopdeck-command']).toBe('touchcut.changePassword');
    await o.status();
    await new TouchcutClient('tc').login('office', 'office2');

    const idx = sim.users.findIndex((u) => u.username === 'office');
    const [gone] = sim.users.splice(idx, 1);
    const e = await failure(
      o.changePassword({ oldPassword: 'office2', newPassword: 'x', confirmPassword: 'x' }, 'c'),
    );
    expect(e.vendorCode).toBe('101');
    if (gone) sim.users.push({ ...gone, password: 'office' });
  });
});

describe('touchcut client: vendor error parser', () => {
  it('maps error bodies, bare statuses, and an error body sent with 200', () => {
    expect(
      parseTouchcutError(400, { code: 1003, msg: 'Required parameter missing: x' }, '')?.vendorCode,
    ).toBe('1003');
    expect(parseTouchcutError(405, null, '')?.message).toMatch(/method not allowed/);
    expect(parseTouchcutError(200, { code: '100', msg: 'Application not ready' }, '')?.vendorCode).toBe(
      '100',
    );
    expect(parseTouchcutError(200, { code: '1', msg: 'x', machineState: 'Idle' }, '')).toBeNull();
    expect(parseTouchcutError(502, null, 'Bad gateway')).toBeNull();
  });
});

describe('touchcut client: reads', () => {
  it('401 without any credential, 403 naming the privilege, 405 for sub paths and methods', async () => {
    gw.apiKey = undefined;
    const c = new TouchcutClient('tc');
    expect((await failure(c.status())).status).toBe(401);
    gw.apiKey = SIM_MONITOR_API_KEY;
    await c.login('office', 'office');
    await c.status();
    const f = await failure(c.monitor(['axes.*']));
    expect(f.status).toBe(403);
    expect(f.message).toMatch(/Monitor System/);
    const sub = await failure(
      c.http.json({ path: '/rest/v1/status/extra' }, (await import('./wire')).statusSchema),
    );
    expect(sub.status).toBe(405);
    expect(sub.message).toMatch(/405/);
    const post = await fetch('http://shopdeck.test/machines/tc/rest/v1/status', { method: 'POST' });
    expect(post.status).toBe(405);
  });

  it('machine-info needs no login', async () => {
    gw.apiKey = undefined;
    const info = await new TouchcutClient('tc').machineInfo();
    expect(info.exeName).toBe('TouchCut7.exe');
    expect(info.tools.length).toBeGreaterThan(0);
  });

  it('sends units and fields, and gets the unit back', async () => {
    const c = new TouchcutClient('tc');
    const s = await c.status('imperial');
    expect(s.units).toBe('imperial');
    expect(gw.fromBrowser.at(-1)?.path).toContain('units=imperial');
    const m = await c.monitor(['axes.axisLong', 'io.din'], 'metric');
    expect(m.axes.map((a) => a.name)).toEqual(['axisLong']);
    expect(m.io.din.length).toBeGreaterThan(0);
    expect(m.io.ain).toEqual([]);
    const none = await c.monitor(['axes.*']);
    expect(none.axes.length).toBe(3);
    expect(none.io).toEqual({ din: [], dout: [], ain: [], aout: [] });
  });

  it('reads a screenshot as PNG, and the controller repeats it within a second', async () => {
    const c = new TouchcutClient('tc');
    const a = await c.screenshot();
    const bytes = new Uint8Array(await a.blob.arrayBuffer());
    expect([...bytes.slice(1, 4)].map((b) => String.fromCharCode(b)).join('')).toBe('PNG');
    const drawn = sim.screenshotsDrawn;
    await c.screenshot();
    expect(sim.screenshotsDrawn).toBe(drawn);
  });

  it('turns a non-PNG screenshot answer into a protocol error', async () => {
    server.use(
      (await import('msw')).http.get(
        'http://shopdeck.test/machines/tc/rest/v1/screenshot',
        () => new Response('<html>', { status: 200 }),
      ),
    );
    const e = await failure(new TouchcutClient('tc').screenshot());
    expect(e.kind).toBe('protocol');
    server.resetHandlers();
  });
});
