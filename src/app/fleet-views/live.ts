import { useMemo, useSyncExternalStore } from 'react';
import { familyLabel } from '../../controllers';
import { getRuntime, type MachineRuntime } from '../../fleet/fleet';
import { derivedStore } from '../../fleet/react';
import type { MachineInfo } from '../../fleet/types';
import {
  arrangeFleet,
  needsState,
  sameGroups,
  stateClass,
  type FleetGroup,
  type StateClass,
} from './arrange';
import type { FleetPrefs } from './prefs';

export { familyLabel };

/** A machine's state now, from its snapshot. */
export function liveState(id: string): StateClass {
  const rt = getRuntime(id);
  return rt ? stateClass(rt.snapshot.getState()) : 'unknown';
}

/**
 * The fleet arranged for the page. Subscribes to the machines' snapshots only when the view
 * sorts or filters by state, and tells React only when the arrangement changed: a tile's update
 * does not re-render the page (nor, through it, the other tiles).
 */
export function useArrangement(machines: readonly MachineInfo[], prefs: FleetPrefs): FleetGroup[] {
  const store = useMemo(() => {
    const sources = needsState(prefs)
      ? machines
          .map((m) => getRuntime(m.id))
          .filter((r): r is MachineRuntime => Boolean(r))
          .map((rt) => rt.snapshot)
      : [];
    return derivedStore(sources, () => arrangeFleet(machines, prefs, liveState, familyLabel), sameGroups);
  }, [machines, prefs]);
  return useSyncExternalStore(store.subscribe, store.getSnapshot);
}
