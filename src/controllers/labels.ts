import type { MachineKind } from '../fleet/types';

/** Each family's name, as its declaration says it (a test keeps them equal). */
export const FAMILY_LABELS: Record<MachineKind, string> = {
  touchcut: 'Kinetic TouchCut',
  g2core: 'g2core CNC',
  duet: 'Duet (RepRapFirmware)',
  xtool: 'xTool D-series',
  prunt: 'Prunt',
};
