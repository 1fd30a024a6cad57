import { useMemo } from 'react';
import type { StoreApi } from 'zustand/vanilla';
import { getRuntime, type MachineRuntime } from '../fleet/fleet';
import type { MachineInfo, MachineSnapshot } from '../fleet/types';

/** The runtimes of these machines (those that exist) and their snapshot stores, kept while the list is. */
export function useRuntimesOf(machines: readonly MachineInfo[]): {
  rts: MachineRuntime[];
  sources: Array<StoreApi<MachineSnapshot>>;
} {
  return useMemo(() => {
    const rts = machines.map((m) => getRuntime(m.id)).filter((r): r is MachineRuntime => Boolean(r));
    return { rts, sources: rts.map((rt) => rt.snapshot) };
  }, [machines]);
}
