import type { ComponentType } from 'react';
import { useStore } from 'zustand';
import { createStore } from 'zustand/vanilla';
import type { ControllerModule, FamilyManifest } from '../fleet/contract';
import { lazyView } from '../fleet/lazy';
import type { MachineKind } from '../fleet/types';
import { duetManifest } from './duet/manifest';
import { g2coreManifest } from './g2core/manifest';
import { pruntManifest } from './prunt/manifest';
import { touchcutManifest } from './touchcut/manifest';
import { xtoolManifest } from './xtool/manifest';

/**
 * The one list of controller families (browser side): each family once, by its manifest (what the
 * shell knows of it before its code loads: small) and its page module (session, wire schemas,
 * commands, tabs: a chunk of its own, loaded when the fleet has a machine of that family, issue
 * 16: a shop of lasers never downloads the printer code). Everything else here comes from it.
 */
const FAMILIES: ReadonlyArray<readonly [FamilyManifest, () => Promise<ControllerModule>]> = [
  [touchcutManifest, () => import('./touchcut/module').then((m) => m.touchcutModule)],
  [g2coreManifest, () => import('./g2core/module').then((m) => m.g2coreModule)],
  [duetManifest, () => import('./duet/module').then((m) => m.duetModule)],
  [xtoolManifest, () => import('./xtool/module').then((m) => m.xtoolModule)],
  [pruntManifest, () => import('./prunt/module').then((m) => m.pruntModule)],
];

/** Every family's manifest, in the list's order. */
export const MANIFESTS: readonly FamilyManifest[] = FAMILIES.map(([m]) => m);

/** The kinds of machine this console knows (the machines list is checked against them). */
export const MACHINE_KINDS = MANIFESTS.map((m) => m.kind) as [MachineKind, ...MachineKind[]];

const byKind = new Map(MANIFESTS.map((m) => [m.kind, m]));

/** A family's manifest (undefined: no such family). */
export function manifestOf(kind: string): FamilyManifest | undefined {
  return byKind.get(kind as MachineKind);
}

/** A family's name, as its manifest says it (the kind itself for a kind the console does not know). */
export function familyLabel(kind: string): string {
  return byKind.get(kind as MachineKind)?.label ?? kind;
}

/** Each family's page module loader (tests replace one). */
export const controllerLoaders: Partial<Record<MachineKind, () => Promise<ControllerModule>>> =
  Object.fromEntries(FAMILIES.map(([m, load]) => [m.kind, load]));

/** Family-level pages outside any machine, routed at `/<kind>/<path>` (their code loads when shown). */
export const familyPages: Array<{
  kind: MachineKind;
  path: string;
  label: string;
  Component: ComponentType;
}> = MANIFESTS.flatMap((m) =>
  (m.pages ?? []).map((p) => ({
    kind: m.kind,
    path: p.path,
    label: p.label,
    Component: lazyView(async () => ({ Page: await p.load() }), 'Page') as ComponentType,
  })),
);

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
    const load = controllerLoaders[kind];
    if (!load) return Promise.reject(new Error(`no controller family "${kind}"`));
    p = load().catch((e: unknown) => {
      loading.delete(kind);
      throw e;
    });
    loading.set(kind, p);
  }
  return p;
}
