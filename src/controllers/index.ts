import type { ComponentType } from 'react';
import { useStore } from 'zustand';
import { createStore } from 'zustand/vanilla';
import type { ControllerModule } from '../fleet/contract';
import { lazyView } from '../fleet/lazy';
import type { MachineKind } from '../fleet/types';

/**
 * The one registry of controller modules (browser side). Each family's code (session, wire
 * schemas, commands, tabs) is a chunk of its own, loaded when the fleet has a machine of that
 * family (issue 16): a shop of lasers never downloads the printer code. What the shell needs
 * before that (the family's name, its pages' routes) is here, small.
 */
export const controllerLoaders: Record<MachineKind, () => Promise<ControllerModule>> = {
  touchcut: () => import('./touchcut/module').then((m) => m.touchcutModule),
  g2core: () => import('./g2core/module').then((m) => m.g2coreModule),
  duet: () => import('./duet/module').then((m) => m.duetModule),
  xtool: () => import('./xtool/module').then((m) => m.xtoolModule),
  prunt: () => import('./prunt/module').then((m) => m.pruntModule),
};

export { FAMILY_LABELS } from './labels';

/** Family-level pages outside any machine, routed at `/<kind>/<path>` (their code loads when shown). */
export const familyPages: Array<{
  kind: MachineKind;
  path: string;
  label: string;
  Component: ComponentType;
}> = [
  {
    kind: 'xtool',
    path: 'discover',
    label: 'Find lasers',
    Component: lazyView(() => import('./xtool/views/Discover'), 'Discover'),
  },
];

/** The modules loaded so far, by kind (components re-render when one arrives). */
export const controllerStore = createStore<Partial<Record<MachineKind, ControllerModule>>>(() => ({}));

/** Makes a loaded module known to the views (boot does it once the family's sessions exist). */
export function registerController(mod: ControllerModule): void {
  controllerStore.setState({ [mod.kind]: mod });
}

/** The family's module once it is loaded (undefined before). */
export function useController(kind: MachineKind): ControllerModule | undefined {
  return useStore(controllerStore, (s) => s[kind]);
}

const loading = new Map<MachineKind, Promise<ControllerModule>>();

/**
 * Loads a family's code (once; a failed load is tried again on the next call: the console server
 * may have been restarted meanwhile).
 */
export function loadController(kind: MachineKind): Promise<ControllerModule> {
  let p = loading.get(kind);
  if (!p) {
    p = controllerLoaders[kind]().catch((e: unknown) => {
      loading.delete(kind);
      throw e;
    });
    loading.set(kind, p);
  }
  return p;
}
