import { WebSocket as NodeWebSocket } from 'ws';
import { startGateway, tempDir } from './test-util';
import type { SessionContext } from '../src/fleet/contract';
import { createContext } from '../src/fleet/fleet';
import { alwaysVisible } from '../src/fleet/link';
import { apiOrigin, setApiOrigin } from '../src/fleet/origin';
import type { SimOptions, Simulator } from '../src/fleet/sim';
import { duetFamily } from '../src/controllers/duet/family';
import { DuetSession } from '../src/controllers/duet/session';

/**
 * For tests (here, not in src/: browser code never imports the gateway, gateway/bundle.test.ts):
 * one Duet behind the real gateway, answered by the simulator `makeSim` makes, and a
 * page's DuetSession on it (not started). Everything it sets up is undone by the `cleanups` the
 * test file runs after each test.
 */
export interface DuetRig<S> {
  sim: () => S;
  session: DuetSession;
  ctx: SessionContext;
}

export interface DuetRigOptions<S> {
  id: string;
  name: string;
  /** The machines file's password for the board (none: the gateway holds no password). */
  configured?: string | undefined;
  makeSim: (o: SimOptions) => S;
  /** The page's sockets send the gateway's Origin, as a browser's do (DSF's `WS /machine`). */
  pageSockets?: boolean;
  /** What the page's context says of the machine. */
  simulated: boolean;
  cleanups: Array<() => Promise<void> | void>;
}

export async function duetRig<S extends Simulator>(o: DuetRigOptions<S>): Promise<DuetRig<S>> {
  const { cleanups } = o;
  const t = tempDir();
  cleanups.push(t.cleanup);
  let sim: S | null = null;
  const gw = await startGateway({
    machines: {
      file: null,
      machines: [
        {
          id: o.id,
          name: `${o.name} sim`,
          kind: 'duet',
          simulated: true,
          url: null,
          wsUrl: null,
          secrets: o.configured ? { password: o.configured } : {},
        },
      ],
    },
    families: { duet: { ...duetFamily, createSimulator: (so) => (sim = o.makeSim(so)) } },
    dataDir: t.dir,
    env: {},
  });
  cleanups.push(gw.close);
  // The page's origin is the gateway.
  const origin = apiOrigin();
  setApiOrigin(gw.url);
  cleanups.push(() => setApiOrigin(origin));
  if (o.pageSockets) {
    const PageSocket = class extends NodeWebSocket {
      constructor(url: string | URL, protocols?: string | string[]) {
        super(url, protocols, { origin: gw.url });
      }
    };
    const previous = globalThis.WebSocket;
    (globalThis as { WebSocket?: unknown }).WebSocket = PageSocket;
    cleanups.push(() => {
      (globalThis as { WebSocket?: unknown }).WebSocket = previous;
    });
  }
  const ctx = createContext(
    { id: o.id, name: o.name, kind: 'duet', simulated: o.simulated },
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

/** Waits (polling every 20 ms) until `pred` holds, failing after `ms`. */
export async function until(pred: () => boolean, ms = 15_000): Promise<void> {
  const end = Date.now() + ms;
  while (!pred()) {
    if (Date.now() > end) throw new Error('condition not met in time');
    await new Promise((r) => setTimeout(r, 20));
  }
}
