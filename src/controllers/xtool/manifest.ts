import type { FamilyManifest } from '../../fleet/contract';

/** The xTool D-series family as the console knows it before its code loads (see `FamilyManifest`). */
export const xtoolManifest: FamilyManifest = {
  kind: 'xtool',
  label: 'xTool D-series',
  jobs: { start: 'xtool.run-file', pause: 'xtool.pause', resume: 'xtool.resume', stop: 'xtool.stop' },
  kiosk: { terms: { stop: 'Stop' }, keep: 'Keep cutting' },
  pages: [
    {
      path: 'discover',
      label: 'Find lasers',
      load: () => import('./views/Discover').then((m) => m.Discover),
    },
  ],
};

// The family's kind, added to `MachineKind` (src/fleet/types.ts).
declare module '../../fleet/types' {
  interface MachineKinds {
    xtool: true;
  }
}
