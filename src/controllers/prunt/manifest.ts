import type { FamilyManifest } from '../../fleet/contract';

/** The Prunt family as the console knows it before its code loads (see `FamilyManifest`). */
export const pruntManifest: FamilyManifest = {
  kind: 'prunt',
  label: 'Prunt',
  jobs: { start: 'prunt.runFile', pause: 'prunt.pause', resume: 'prunt.resume', stop: 'prunt.cancel' },
  kiosk: { terms: { stop: 'Cancel file' }, keep: 'Keep printing' },
};

// The family's kind, added to `MachineKind` (src/fleet/types.ts).
declare module '../../fleet/types' {
  interface MachineKinds {
    prunt: true;
  }
}
