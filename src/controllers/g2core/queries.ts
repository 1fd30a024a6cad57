import type { SessionContext } from '../../fleet/contract';
import { useMachineQuery, type Fetcher, type QueryView } from '../../fleet/kernel';
import type { Job, SettingsGroup } from './wire';

/**
 * The g2core reads made on demand, through the machine's query layer (`ctx.queries`): keyed
 * under the machine, shared by everything that shows them (one request per key at a time),
 * stale after the times below, refetched after a command that declares them stale
 * (`invalidates`), dropped on stop and when nothing showed them for a while.
 *
 * - `['jobs']`: the job queue. The session's slow poll reads it through this key too (the
 *   running job's progress is in the machine snapshot), so the Jobs tab and the poll share one
 *   read. Its fetcher also writes the list into the session's store (for availability and the
 *   snapshot), only while the run that read it is current.
 * - `['settings', 'groups']`: the top-level groups (`GET /machine?shallow=true`).
 * - `['settings', 'group', name]`: one group's values (`GET /machine?filter={"<name>":null}`).
 */

export const JOBS_KEY = ['jobs'] as const;
export const SETTINGS_KEY = ['settings'] as const;
export const SETTINGS_GROUPS_KEY = ['settings', 'groups'] as const;
/** Every group's values (what a settings write makes stale). */
export const SETTINGS_GROUP_KEY = ['settings', 'group'] as const;
export const settingsGroupKey = (name: string) => [...SETTINGS_GROUP_KEY, name] as const;

/** The job list: the slow poll reads it about once a second; a view shown meanwhile reuses that read. */
export const JOBS_STALE_MS = 500;
/** The list of groups changes only with the firmware. */
export const GROUPS_STALE_MS = 5 * 60_000;
/** A group's values (another console may change them; Reload reads at once). */
export const GROUP_STALE_MS = 30_000;

/** What the hooks need of the session. */
export interface QueryHost {
  readonly ctx: Pick<SessionContext, 'queries'>;
  readonly readJobs: Fetcher<Job[]>;
  readonly readGroups: Fetcher<string[]>;
  readGroup(name: string): Fetcher<SettingsGroup>;
}

export function useJobs(s: QueryHost): QueryView<Job[]> {
  return useMachineQuery(s.ctx.queries, JOBS_KEY, s.readJobs, { staleTimeMs: JOBS_STALE_MS });
}

export function useSettingsGroups(s: QueryHost): QueryView<string[]> {
  return useMachineQuery(s.ctx.queries, SETTINGS_GROUPS_KEY, s.readGroups, { staleTimeMs: GROUPS_STALE_MS });
}

export function useSettingsGroup(s: QueryHost, name: string): QueryView<SettingsGroup> {
  return useMachineQuery(s.ctx.queries, settingsGroupKey(name), s.readGroup(name), {
    staleTimeMs: GROUP_STALE_MS,
  });
}
