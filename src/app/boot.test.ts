import { afterEach, beforeEach, describe, expect, it, vi } from 'vitest';
import { controllerLoaders, controllerStore } from '../controllers';
import type { ControllerModule, MachineSession, SessionContext } from '../fleet/contract';
import { pendingRuntime } from '../fleet/fleet';
import { alwaysVisible } from '../fleet/link';
import { startFamily } from './boot';

// Each case uses a family of its own: a loaded family stays loaded (as in the page).
const real = { ...controllerLoaders };
const LASER = { id: 'laser', name: 'Laser', kind: 'xtool' as const, simulated: true };

function fakeModule(started: string[]): ControllerModule {
  return {
    kind: 'xtool',
    label: 'Fake laser',
    createSession: (ctx: SessionContext): MachineSession => ({
      machine: ctx.machine,
      ctx,
      commands: {},
      start: () => started.push(ctx.machine.id),
      stop: () => undefined,
    }),
    tabs: [],
  };
}

describe('starting a family when its code has loaded', () => {
  beforeEach(() => {
    vi.useFakeTimers();
    controllerStore.setState({}, true);
  });
  afterEach(() => {
    Object.assign(controllerLoaders, real);
    vi.useRealTimers();
  });

  it('gives its machines their sessions, starts them, then tells the views', async () => {
    const started: string[] = [];
    const mod = fakeModule(started);
    controllerLoaders.xtool = () => Promise.resolve(mod);
    const rt = pendingRuntime(LASER, { visibility: alwaysVisible });
    let sessionWhenViewsHeard: MachineSession | null | undefined;
    const unsub = controllerStore.subscribe(() => (sessionWhenViewsHeard = rt.session));
    expect(rt.session).toBeNull();
    startFamily('xtool', [rt]);
    await vi.runAllTimersAsync();
    unsub();
    expect(rt.session).not.toBeNull();
    expect(sessionWhenViewsHeard).toBe(rt.session);
    expect(started).toEqual(['laser']);
    expect(controllerStore.getState().xtool).toBe(mod);
  });

  it('tries a failed load again, then says on the machine why it shows nothing', async () => {
    const load = vi.fn(() => Promise.reject(new Error('Failed to fetch dynamically imported module')));
    controllerLoaders.duet = load;
    const rt = pendingRuntime({ ...LASER, kind: 'duet' }, { visibility: alwaysVisible });
    startFamily('duet', [rt]);
    await vi.runAllTimersAsync();
    expect(load).toHaveBeenCalledTimes(4);
    expect(rt.session).toBeNull();
    expect(rt.error).toMatch(
      /could not load its Duet \(RepRapFirmware\) code \(Failed to fetch.*\)\. Reload the page\./,
    );
    expect(rt.snapshot.getState().link).toBe('protocol-error');
    expect(rt.log.store.getState().entries.some((e) => e.text.includes('could not load'))).toBe(true);
  });

  it('recovers when a later try loads', async () => {
    const started: string[] = [];
    const mod = fakeModule(started);
    let calls = 0;
    controllerLoaders.prunt = () =>
      ++calls < 3 ? Promise.reject(new Error('offline')) : Promise.resolve(mod);
    const rt = pendingRuntime({ ...LASER, kind: 'prunt' }, { visibility: alwaysVisible });
    startFamily('prunt', [rt]);
    await vi.runAllTimersAsync();
    expect(calls).toBe(3);
    expect(rt.error).toBeNull();
    expect(started).toEqual(['laser']);
  });
});
