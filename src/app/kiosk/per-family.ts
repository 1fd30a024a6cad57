import type { ComponentType } from 'react';
import type { MachineSession, TabProps } from '../../fleet/contract';
import { lazyView } from '../../fleet/lazy';
import type { MachineKind, Role } from '../../fleet/types';

/** A job control of the shared row (src/app/kiosk/JobControls.tsx). */
export type JobControlKind = 'pause' | 'resume' | 'stop' | 'estop';

/**
 * The role every family declares for its job controls (pause, resume, stop job, emergency stop):
 * the row shown before a family's code has loaded is shown from it (per-family.test.ts checks it
 * against the declarations).
 */
export const JOB_CONTROL_ROLE: Role = 'operator';

/**
 * One vocabulary across families: the row's words. The firmware's own term for each is the
 * family's `terms`, shown as a subtitle ("Stop job — Kill (^D)").
 */
export const JOB_CONTROL_WORDS: Record<JobControlKind, string> = {
  pause: 'Pause',
  resume: 'Resume',
  stop: 'Stop job',
  estop: 'Emergency stop',
};

/**
 * What the kiosk page and the machine page's job control row offer for each family: the ids of
 * its declared job commands (the same declarations, roles, confirmations and audit as every other
 * button) and, optionally, a view of the family's own shown below them in the kiosk (a chunk of
 * its own). A family missing here shows state and progress only.
 */
export interface KioskFamily {
  pause: string;
  resume: string;
  /** The job's stop (cancel, kill): hazard `stop`, confirmed as the family declares. */
  stop: string;
  /** The machine's emergency stop, where the family has one the console may send. */
  estop?: string;
  /** The firmware's own term for each control (the subtitle under the shared word). */
  terms: Partial<Record<JobControlKind, string>>;
  /** What dismissing the job stop's question keeps ("Keep printing"). */
  keep: string;
  Extra?: ComponentType<TabProps<MachineSession>>;
}

export const KIOSK_FAMILIES: Partial<Record<MachineKind, KioskFamily>> = {
  xtool: {
    pause: 'xtool.pause',
    resume: 'xtool.resume',
    stop: 'xtool.stop',
    terms: { stop: 'Stop' },
    keep: 'Keep cutting',
  },
  // Duet cancels only a paused print (as Duet Web Control): pause first, then cancel.
  duet: {
    pause: 'duet.pause',
    resume: 'duet.resume',
    stop: 'duet.cancel',
    estop: 'duet.estop',
    terms: { pause: 'M25', resume: 'M24', stop: 'Cancel print (M0)', estop: 'M112' },
    keep: 'Keep printing',
  },
  prunt: {
    pause: 'prunt.pause',
    resume: 'prunt.resume',
    stop: 'prunt.cancel',
    terms: { stop: 'Cancel file' },
    keep: 'Keep printing',
  },
  g2core: {
    pause: 'g2core.feedhold',
    resume: 'g2core.resume',
    stop: 'g2core.kill',
    terms: { pause: 'Feedhold (!)', resume: 'Cycle start (~)', stop: 'Kill (^D)' },
    keep: 'Keep cutting',
    // The family's session type erased, as the registry does (defineController).
    Extra: lazyView(
      () => import('../../controllers/g2core/views/Overrides'),
      'Overrides',
    ) as unknown as ComponentType<TabProps<MachineSession>>,
  },
  // TouchCut: its REST API commands nothing; the operator uses the table's own panel.
};
