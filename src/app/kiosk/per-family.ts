import type { ComponentType } from 'react';
import { MANIFESTS } from '../../controllers';
import type { JobControlKind, MachineSession, TabProps } from '../../fleet/contract';
import { lazyView } from '../../fleet/lazy';
import type { MachineKind, Role } from '../../fleet/types';

export type { JobControlKind };

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
 * What the kiosk page and the machine page's job control row offer for each family, from its
 * manifest: the ids of its declared job commands (`jobs`: the same declarations, roles,
 * confirmations and audit as every other button), its `kiosk` words and, optionally, a view of
 * the family's own shown below them in the kiosk (a chunk of its own). A family whose manifest
 * has no `jobs` or no `kiosk` shows state and progress only.
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

export const KIOSK_FAMILIES: Partial<Record<MachineKind, KioskFamily>> = Object.fromEntries(
  MANIFESTS.flatMap(({ kind, jobs, kiosk }): Array<[MachineKind, KioskFamily]> => {
    if (!jobs || !kiosk) return [];
    const { extra } = kiosk;
    const row: KioskFamily = {
      pause: jobs.pause,
      resume: jobs.resume,
      stop: jobs.stop,
      ...(jobs.estop !== undefined && { estop: jobs.estop }),
      terms: kiosk.terms,
      keep: kiosk.keep,
      // The family's session type erased, as the registry does (defineController).
      ...(extra && {
        Extra: lazyView(extra, 'KioskExtra') as unknown as ComponentType<TabProps<MachineSession>>,
      }),
    };
    return [[kind, row]];
  }),
);
