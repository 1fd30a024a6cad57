import { afterEach, describe, expect, it } from 'vitest';
import { createContext } from '../../fleet/fleet';
import { alwaysVisible } from '../../fleet/link';
import { DuetSession } from './session';
import { DuetSimulator } from './sim/simulator';
import { duetRig, until } from '../../../gateway/test-util-duet';

/**
 * The Duet browser session through the real gateway, which holds the DSF session: the page
 * never has a session key, and connect, socket, polling fallback, commands and the login form
 * still work. The gateway answers from a simulated Duet that enforces keys (it has a password).
 */

const cleanups: Array<() => Promise<void> | void> = [];
afterEach(async () => {
  for (const c of cleanups.splice(0).reverse()) await c();
});

const rig = (simPassword: string, configured?: string) =>
  duetRig({
    id: 'dsim',
    name: 'Duet',
    configured,
    simulated: false,
    pageSockets: true,
    makeSim: (o) => new DuetSimulator({ ...o, password: simPassword, tickMs: 100 }),
    cleanups,
  });

describe('DuetSession through the gateway (the gateway holds the DSF session)', () => {
  it('goes online without ever holding a session key; socket and commands work', async () => {
    const { sim, session, ctx } = await rig('sim-pass-31', 'sim-pass-31');
    session.start();
    await until(() => ctx.snapshot.getState().link === 'online');
    expect(session.client.sessionKey).toBeNull();
    expect(session.client.socketUrl()).not.toContain('sessionKey');
    await until(
      () => session.store.getState().transport === 'socket' && session.store.getState().model !== null,
    );
    // The socket is the gateway's, with its key: the simulator counts one user session.
    const dsf = (sim().model['sbc'] as { dsf: { userSessions: unknown[] } }).dsf;
    expect(dsf.userSessions).toHaveLength(1);
    await ctx.commands.run(session.cmd.console, { code: 'M115' });
    expect(sim().codes).toEqual(['M115']);
  });

  it('an expired DSF session is renewed by the gateway; the page stays online', async () => {
    const { sim, session, ctx } = await rig('sim-pass-32', 'sim-pass-32');
    session.start();
    await until(() => ctx.snapshot.getState().link === 'online');
    sim().expireSessions();
    sim().closeSockets(4000, 'simulated socket close');
    // The socket reconnects (the gateway renews its key on the way); a command then goes through.
    await until(() => ctx.snapshot.getState().link === 'online' && sim().openSockets === 1);
    await ctx.commands.run(session.cmd.console, { code: 'M115' });
    expect(sim().codes).toEqual(['M115']);
    expect(session.client.sessionKey).toBeNull();
  });

  it('the configured password is refused, then accepted again: the page comes back by itself (issue 15)', async () => {
    const { sim, session, ctx } = await rig('sim-pass-35', 'sim-pass-35');
    session.start();
    await until(() => ctx.snapshot.getState().link === 'online');
    // Someone changes the Duet's password: the gateway's session goes, its renewal is refused.
    sim().password = 'changed-on-the-duet';
    sim().expireSessions();
    sim().closeSockets(4000, 'simulated socket close');
    await until(() => ctx.snapshot.getState().link === 'needs-login', 20_000);
    expect(ctx.snapshot.getState().problem?.message).toMatch(/machines file/);
    expect(ctx.snapshot.getState().retryAt).not.toBeNull();
    // …and changes it back: no reload, no typed password.
    sim().password = 'sim-pass-35';
    await until(() => ctx.snapshot.getState().link === 'online', 20_000);
  }, 45_000);

  it('without sockets it polls through the gateway (no key needed to know it is connected)', async () => {
    const { sim, session, ctx } = await rig('sim-pass-34', 'sim-pass-34');
    const previous = session.client.connected;
    expect(previous).toBe(false);
    session.start();
    await until(() => ctx.snapshot.getState().link === 'online');
    sim().refuseSockets = true;
    sim().closeSockets(4000, 'simulated socket close');
    await until(() => session.store.getState().transport === 'polling', 18_000);
    expect(ctx.snapshot.getState().link).toBe('online');
    expect(sim().requests).toContain('GET /machine/model');
    expect(session.client.sessionKey).toBeNull();
  }, 25_000);

  it('the login form: a wrong password is refused, the right one is kept by the gateway', async () => {
    const { sim, session, ctx } = await rig('typed-pass-33');
    session.start();
    await until(() => ctx.snapshot.getState().link === 'needs-login');
    expect(session.store.getState().needsPassword).toBe(true);
    await expect(session.login({ password: 'nope-nope' })).rejects.toThrow(/refused/);
    await session.login({ password: 'typed-pass-33' });
    await until(() => ctx.snapshot.getState().link === 'online');
    expect(session.client.sessionKey).toBeNull();
    await ctx.commands.run(session.cmd.console, { code: 'M115' });
    expect(sim().codes).toEqual(['M115']);
    // Another page (no password typed) uses the gateway's session.
    const other = new DuetSession(
      createContext(
        { id: 'dsim', name: 'Duet', kind: 'duet', simulated: false },
        { visibility: alwaysVisible, principal: () => ({ name: 'other', role: 'viewer' }) },
      ),
    );
    cleanups.push(() => other.stop());
    other.start();
    await until(() => other.ctx.snapshot.getState().link === 'online');
    expect(sim().requests.filter((r) => r === 'GET /machine/connect')).toHaveLength(3);
  });
});
