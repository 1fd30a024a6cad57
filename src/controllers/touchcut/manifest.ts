import type { FamilyManifest } from '../../fleet/contract';

/**
 * The Kinetic TouchCut family as the console knows it before its code loads (see
 * `FamilyManifest`). Its REST API commands nothing (no job controls): the operator uses the
 * table's own panel.
 */
export const touchcutManifest: FamilyManifest = {
  kind: 'touchcut',
  label: 'Kinetic TouchCut',
  history: { statisticsDays: 'TouchCut days' },
};

// The family's kind, added to `MachineKind` (src/fleet/types.ts).
declare module '../../fleet/types' {
  interface MachineKinds {
    touchcut: true;
  }
}
