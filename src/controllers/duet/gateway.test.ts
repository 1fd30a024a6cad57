import { afterEach, describe, expect, it } from 'vitest';
import { WebSocket as NodeWebSocket } from 'ws';
import { startGateway, tempDir } from '../../../gateway/test-util';
import type { SessionContext } from '../../fleet/contract';
import { createContext } from '../../fleet/fleet';
import { alwaysVisible } from '../../fleet/link';
import { apiOrigin, setApiOrigin } from '../../fleet/origin';
import { duetFamily } from './family';
import { DuetSession } from './session';
import { DuetSimulator } from './sim/simulator';

/**
 * The Duet browser session through the real gateway, which holds the DSF session: the page
 * never has a session key, and connect, socket, polling fallback, commands and the login form
 * still work. The gateway answers from a simulated Duet that enforces keys (it has a password).
 */

const cleanups: Array<() => Promise<void> | void> = [];
afterEach(async () => {
  for (const c of cleanups.splice(0).reverse()) await c();
});

async function until(pred: () => boolean, ms = 15_000): Promise<void> {
  const end = Date.now() + ms;
  while (!pred()) {
    if (Date.now() > end) throw new Error('condition not met in time');
    await new Promise((r) => setTimeout(r, 20));
  }
}

interface Rig {
  sim: () => DuetSimulator;
  session: DuetSession;
  ctx: SessionContext;
}

async function rig(simPassword: string, configured?: string): Promise<Rig> {
  const t = tempDir();
  cleanups.push(t.cleanup);
  let sim: DuetSimulator | null = null;
  const gw = await startGateway({
    machines: {
      file: null,
      machines: [
        {
          id: 'dsim',
          name: 'Duet sim',
          kind: 'duet',
          simulated: true,
          url: null,
          wsUrl: null,
          secrets: configured ? { password: configured } : {},
        },
      ],
    },
    families: {
      duet: {
        ...duetFamily,
        createSimulator: (o) => (sim = new DuetSimulator({ ...o, password: simPassword, tickMs: 100 })),
      },
    },
    dataDir: t.dir,
    env: {},
  });
  cleanups.push(gw.close);
  // The page's origin is the gateway; its sockets send that Origin, as a browser does.
  const origin = apiOrigin();
  const PageSocket = class extends NodeWebSocket {
    constructor(url: string | URL, protocols?: string | string[]) {
      super(url, protocols, { origin: gw.url });
    }
  };
  const previous = globalThis.WebSocket;
  setApiOrigin(gw.url);
  (globalThis as { WebSocket?: unknown }).WebSocket = PageSocket;
  cleanups.push(() => {
    setApiOrigin(origin);
    (globalThis as { WebSocket?: unknown }).WebSocket = previous;
  });
  const ctx = createContext(
    { id: 'dsim', name: 'Duet', kind: 'duet', simulated: false },
    { visibility: alwaysVisible, principal: () => ({ name: 'tester', role: 'supervisor' }) },
  );
  const session = new DuetSession(ctx);
  cleanups.push(() => session.stop());
  return {
    sim: () => {
      if (!sim) throw new Error('the gateway made no simulator');
      return sim;
    },
    session,
    ctx,
  };
}

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
