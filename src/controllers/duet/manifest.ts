import type { FamilyManifest } from '../../fleet/contract';

/** The Duet family as the console knows it before its code loads (see `FamilyManifest`). */
export const duetManifest: FamilyManifest = {
  kind: 'duet',
  label: 'Duet (RepRapFirmware)',
  // Duet cancels only a paused print (as Duet Web Control): pause first, then cancel.
  jobs: {
    start: 'duet.start',
    pause: 'duet.pause',
    resume: 'duet.resume',
    stop: 'duet.cancel',
    estop: 'duet.estop',
  },
  kiosk: {
    terms: { pause: 'M25', resume: 'M24', stop: 'Cancel print (M0)', estop: 'M112' },
    keep: 'Keep printing',
  },
};

// The family's kind, added to `MachineKind` (src/fleet/types.ts).
declare module '../../fleet/types' {
  interface MachineKinds {
    duet: true;
  }
}
