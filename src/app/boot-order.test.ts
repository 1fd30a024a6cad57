// @vitest-environment happy-dom
import { afterEach, describe, expect, it, vi } from 'vitest';
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
    access: () => ({ role: 'viewer', command: false, label: 'read' }),
    createSession: (ctx: SessionContext): MachineSession => ({
      machine: ctx.machine,
      ctx,
      commands: {},
      start: () => {
        if (kind === 'xtool') laserStarted = ctx;
      },
      stop: () => undefined,
    }),
    tabs: [],
  };
}

let laserStarted: SessionContext | null = null;

const answer = (body: unknown): Response =>
  new Response(JSON.stringify(body), { status: 200, headers: { 'Content-Type': 'application/json' } });

afterEach(() => {
  vi.unstubAllGlobals();
  vi.restoreAllMocks();
});

describe('boot', () => {
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
    vi.stubGlobal(
      'fetch',
      vi.fn((url: string) =>
        Promise.resolve(
          url.startsWith('/api/machines')
            ? answer({
                machines: [
                  { id: 'printer', name: 'Printer', kind: 'duet', simulated: true },
                  { id: 'laser', name: 'Laser', kind: 'xtool', simulated: true },
                  { id: 'mill', name: 'Mill', kind: 'g2core', simulated: true },
                ],
              })
            : answer({ mode: 'open', user: null }),
        ),
      ),
    );
    const { boot } = await import('./boot');
    await boot();
    await vi.waitFor(() => expect(order).toEqual(['xtool']));
    // Still only the laser's family while it loads.
    await new Promise((r) => setTimeout(r, 50));
    expect(order).toEqual(['xtool']);
    (releaseXtool as (() => void) | null)?.();
    await vi.waitFor(() => expect(laserStarted).not.toBeNull());
    // The laser's session runs but has no answer yet: the other families wait (they would have
    // started 1.5 s after the laser's code loaded, when the browser was idle).
    await new Promise((r) => setTimeout(r, 2000));
    expect(order).toEqual(['xtool']);
    (laserStarted as SessionContext | null)?.snapshot.setState({ link: 'online' });
    await vi.waitFor(() => expect(order).toEqual(['xtool', 'duet', 'g2core']), { timeout: 3000 });
  });
});
