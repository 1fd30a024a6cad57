import type { ComponentType } from 'react';
import type { MachineSession, TabProps } from '../../fleet/contract';
import { lazyView } from '../../fleet/lazy';
import type { MachineKind } from '../../fleet/types';

/**
 * What the kiosk page offers for each family: the ids of its declared job commands (the same
 * declarations, roles, confirmations and audit as the machine page's buttons) and, optionally, a
 * view of the family's own shown below them (a chunk of its own). A family missing here shows
 * state and progress only.
 */
export interface KioskFamily {
  pause: string;
  resume: string;
  /** The job's stop (cancel, kill): hazard `stop`, confirmed as the family declares. */
  stop: string;
  Extra?: ComponentType<TabProps<MachineSession>>;
}

export const KIOSK_FAMILIES: Partial<Record<MachineKind, KioskFamily>> = {
  xtool: { pause: 'xtool.pause', resume: 'xtool.resume', stop: 'xtool.stop' },
  // Duet cancels only a paused print (as Duet Web Control): pause first, then cancel.
  duet: { pause: 'duet.pause', resume: 'duet.resume', stop: 'duet.cancel' },
  prunt: { pause: 'prunt.pause', resume: 'prunt.resume', stop: 'prunt.cancel' },
  g2core: {
    pause: 'g2core.feedhold',
    resume: 'g2core.resume',
    stop: 'g2core.kill',
    // The family's session type erased, as the registry does (defineController).
    Extra: lazyView(
      () => import('../../controllers/g2core/views/Overrides'),
      'Overrides',
    ) as unknown as ComponentType<TabProps<MachineSession>>,
  },
  // TouchCut: its REST API commands nothing; the operator uses the table's own panel.
};
