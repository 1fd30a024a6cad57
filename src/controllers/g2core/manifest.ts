import type { FamilyManifest } from '../../fleet/contract';

/** The g2core family as the console knows it before its code loads (see `FamilyManifest`). */
export const g2coreManifest: FamilyManifest = {
  kind: 'g2core',
  label: 'g2core CNC',
  jobs: { start: 'g2core.run-job', pause: 'g2core.feedhold', resume: 'g2core.resume', stop: 'g2core.kill' },
  kiosk: {
    terms: { pause: 'Feedhold (!)', resume: 'Cycle start (~)', stop: 'Kill (^D)' },
    keep: 'Keep cutting',
    // The feed and spindle overrides under the controls.
    extra: () => import('./views/KioskExtra'),
  },
};

// The family's kind, added to `MachineKind` (src/fleet/types.ts).
declare module '../../fleet/types' {
  interface MachineKinds {
    g2core: true;
  }
}
