import type { FamilyManifest } from '../../fleet/contract';

/** The Prunt family as the console knows it before its code loads (see `FamilyManifest`). */
export const pruntManifest: FamilyManifest = {
  kind: 'prunt',
  label: 'Prunt',
  jobs: { start: 'prunt.runFile', pause: 'prunt.pause', resume: 'prunt.resume', stop: 'prunt.cancel' },
  kiosk: { terms: { stop: 'Cancel file' }, keep: 'Keep printing' },
};
