// @vitest-environment happy-dom
import { afterEach, beforeEach, describe, expect, it, vi } from 'vitest';
import { controllerLoaders } from '../controllers';
import type { ControllerModule, MachineSession, SessionContext } from '../fleet/contract';
import type { MachineKind } from '../fleet/types';

/**
 * On a machine's page (a kiosk tablet), that machine's family loads first; the other families
 * come after it, when the browser is idle (their alarms still reach every page).
 */
function fakeModule(kind: MachineKind): ControllerModule {
  return {
    kind,
    label: kind,
    createSession: (ctx: SessionContext): MachineSession => ({
      machine: ctx.machine,
      ctx,
      commands: {},
      start: () => {
        if (kind === 'xtool') laserStarted = ctx;
        sessionsStarted.push(ctx.machine.id);
      },
      stop: () => undefined,
    }),
    tabs: [],
  };
}

let laserStarted: SessionContext | null = null;
const sessionsStarted: string[] = [];

const answer = (body: unknown): Response =>
  new Response(JSON.stringify(body), { status: 200, headers: { 'Content-Type': 'application/json' } });

/** A machine in the machines list (simulated unless it says otherwise; `watch`: the server's reading). */
type Listed = { id: string; name: string; kind: MachineKind } & Record<string, unknown>;

/** The gateway's answers at boot: an open console and these machines. */
function stubFleet(machines: readonly Listed[]): void {
  vi.stubGlobal(
    'fetch',
    vi.fn((url: string) =>
      Promise.resolve(
        url.startsWith('/api/machines')
          ? answer({ machines: machines.map((m) => ({ simulated: true, ...m })) })
          : answer({ mode: 'open', user: null }),
      ),
    ),
  );
}

/**
 * A fresh page at `path` listing `machines` (a new module graph: no earlier test's first screen),
 * with the order in which the families' code is asked for.
 */
async function freshPage(path: string, machines: readonly Listed[]) {
  history.replaceState(null, '', path);
  vi.resetModules();
  const { controllerLoaders: loaders } = await import('../controllers');
  const order: string[] = [];
  for (const kind of new Set(machines.map((m) => m.kind)))
    loaders[kind] = () => (order.push(kind), Promise.resolve(fakeModule(kind)));
  stubFleet(machines);
  const { boot } = await import('./boot');
  const { firstScreenShown } = await import('./first-screen');
  return { order, boot, firstScreenShown };
}

afterEach(() => {
  vi.useRealTimers();
  vi.unstubAllGlobals();
  vi.restoreAllMocks();
});

describe('boot', () => {
  // The seconds the page waits pass on a fake clock (vi.waitFor advances it as it polls).
  beforeEach(() => {
    vi.useFakeTimers({ toFake: ['setTimeout', 'clearTimeout', 'Date'] });
  });
  it('loads the family of the machine in view first, the others once it shows its data', async () => {
    history.replaceState(null, '', '/m/laser/files');
    const order: string[] = [];
    let releaseXtool: (() => void) | null = null;
    controllerLoaders.xtool = () =>
      new Promise((ok) => {
        order.push('xtool');
        releaseXtool = () => ok(fakeModule('xtool'));
      });
    controllerLoaders.duet = () => (order.push('duet'), Promise.resolve(fakeModule('duet')));
    controllerLoaders.g2core = () => (order.push('g2core'), Promise.resolve(fakeModule('g2core')));
    stubFleet([
      { id: 'printer', name: 'Printer', kind: 'duet' },
      { id: 'laser', name: 'Laser', kind: 'xtool' },
      { id: 'mill', name: 'Mill', kind: 'g2core' },
    ]);
    const { boot } = await import('./boot');
    await boot();
    await vi.waitFor(() => expect(order).toEqual(['xtool']));
    // Still only the laser's family while it loads.
    await vi.advanceTimersByTimeAsync(50);
    expect(order).toEqual(['xtool']);
    (releaseXtool as (() => void) | null)?.();
    await vi.waitFor(() => expect(laserStarted).not.toBeNull());
    // The laser's session runs but has no answer yet: the other families wait (they would have
    // started 1.5 s after the laser's code loaded, when the browser was idle).
    await vi.advanceTimersByTimeAsync(2000);
    expect(order).toEqual(['xtool']);
    (laserStarted as SessionContext | null)?.snapshot.setState({ link: 'online' });
    // When the browser is idle after it (happy-dom has no idle callback: whenIdle's 1.5 s), well
    // before the 6 s at which they would start anyway.
    await vi.advanceTimersByTimeAsync(1500);
    expect(order).toEqual(['xtool', 'duet', 'g2core']);
  });

  it('a kiosk tablet runs its own machine only; the others start when it leaves the kiosk', async () => {
    history.replaceState(null, '', '/m/kiosk-laser?kiosk');
    sessionsStarted.length = 0;
    controllerLoaders.xtool = () => Promise.resolve(fakeModule('xtool'));
    controllerLoaders.duet = () => Promise.resolve(fakeModule('duet'));
    stubFleet([
      { id: 'kiosk-printer', name: 'Printer', kind: 'duet' },
      { id: 'kiosk-laser', name: 'Laser', kind: 'xtool' },
      { id: 'kiosk-laser-2', name: 'Laser 2', kind: 'xtool' },
    ]);
    const { boot } = await import('./boot');
    const { getRuntime } = await import('../fleet/fleet');
    await boot();
    await vi.waitFor(() => expect(sessionsStarted).toEqual(['kiosk-laser']));
    // It shows its data, the browser is idle, seconds pass: still its machine alone (not even
    // the other laser of its family).
    getRuntime('kiosk-laser')?.snapshot.setState({ link: 'online' });
    await vi.advanceTimersByTimeAsync(3500);
    expect(sessionsStarted).toEqual(['kiosk-laser']);
    const { navigate } = await import('./router');
    navigate('/m/kiosk-laser?kiosk&x=1'); // still the kiosk
    await vi.advanceTimersByTimeAsync(50);
    expect(sessionsStarted).toEqual(['kiosk-laser']);
    navigate('/');
    await vi.waitFor(() =>
      expect([...sessionsStarted].sort()).toEqual(['kiosk-laser', 'kiosk-laser-2', 'kiosk-printer']),
    );
  });

  it('a kiosk tablet paints its machine from the server reading first; its family loads right after', async () => {
    const watch = { state: 'running', job: null, progress: null, alarm: null, ageMs: 800 };
    const { order, boot, firstScreenShown } = await freshPage('/m/ks-laser?kiosk', [
      { id: 'ks-laser', name: 'Laser', kind: 'xtool', watch },
      // Another machine's family is not loaded on the kiosk at all.
      { id: 'ks-printer', name: 'Printer', kind: 'duet' },
    ]);
    await boot();
    // Nothing of the family before the kiosk has painted the server's reading.
    await vi.advanceTimersByTimeAsync(1000);
    expect(order).toEqual([]);
    firstScreenShown();
    // At once after it (no idle wait), and its machine's family only.
    await vi.advanceTimersByTimeAsync(0);
    expect(order).toEqual(['xtool']);
    await vi.advanceTimersByTimeAsync(3000);
    expect(order).toEqual(['xtool']);
  });

  it('a kiosk tablet whose first screen never shows still loads its machine’s code', async () => {
    const watch = { state: 'idle', job: null, progress: null, alarm: null, ageMs: 800 };
    const { order, boot } = await freshPage('/m/ks-mill?kiosk', [
      { id: 'ks-mill', name: 'Mill', kind: 'g2core', watch },
    ]);
    await boot();
    await vi.advanceTimersByTimeAsync(1000);
    expect(order).toEqual([]);
    await vi.advanceTimersByTimeAsync(2000);
    await vi.waitFor(() => expect(order).toEqual(['g2core']), { timeout: 3000 });
  });

  it('the fleet page paints from the server readings first; the families load after it', async () => {
    const { order, boot, firstScreenShown } = await freshPage('/', [
      {
        id: 'fs-table',
        name: 'Table',
        kind: 'touchcut',
        watch: { state: 'running', job: 'A.nc', progress: 0.5, alarm: null, ageMs: 1200 },
      },
      // A reading the page cannot use is left out alone: the machine still comes.
      { id: 'fs-printer', name: 'Printer', kind: 'prunt', watch: { state: 'melting' } },
    ]);
    const { fleetStore, getRuntime } = await import('../fleet/fleet');
    await boot();
    const machines = fleetStore.getState().machines;
    expect(machines.find((m) => m.id === 'fs-table')?.watch).toMatchObject({ state: 'running', job: 'A.nc' });
    expect(machines.find((m) => m.id === 'fs-printer')).toMatchObject({ name: 'Printer' });
    expect(machines.find((m) => m.id === 'fs-printer')?.watch).toBeUndefined();
    // And said in that machine's log (the other's has nothing to say).
    const warned = (id: string) =>
      getRuntime(id)
        ?.log.store.getState()
        .entries.filter((e) => e.level === 'warning' && /reading .* was malformed/.test(e.text)).length;
    expect(warned('fs-printer')).toBe(1);
    expect(warned('fs-table')).toBe(0);
    // No family's code before the first screen is up (longer than an idle wait, shorter than the
    // few seconds after which the machines start anyway).
    await vi.advanceTimersByTimeAsync(2000);
    expect(order).toEqual([]);
    firstScreenShown();
    await vi.advanceTimersByTimeAsync(1500);
    await vi.waitFor(() => expect([...order].sort()).toEqual(['prunt', 'touchcut']), { timeout: 3000 });
  });
});

// After the cases above that change the statically imported registry: this one resets the modules.
describe('boot, the first requests', () => {
  it('asks for the machine list beside the session, not after its answer (issue 34: one round trip)', async () => {
    history.replaceState(null, '', '/');
    vi.resetModules();
    const asked: string[] = [];
    let answerSession: (r: Response) => void = () => undefined;
    vi.stubGlobal(
      'fetch',
      vi.fn((url: string) => {
        asked.push(url);
        if (url.startsWith('/api/machines')) return Promise.resolve(answer({ machines: [] }));
        return new Promise<Response>((r) => (answerSession = r));
      }),
    );
    const { boot } = await import('./boot');
    const { fleetStore } = await import('../fleet/fleet');
    const done = boot();
    await new Promise((r) => setTimeout(r, 0));
    // The session has not answered yet, and the machine list is on its way.
    expect(asked).toContain('/api/session');
    expect(asked).toContain('/api/machines');
    answerSession(answer({ mode: 'open', user: null }));
    await done;
    expect(fleetStore.getState().status).toBe('ready');
  });
});
