import { createStore } from 'zustand/vanilla';
import { MACHINE_KINDS } from '../../controllers';
import type { MachineKind } from '../../fleet/types';

/**
 * How the fleet page shows the fleet: view, sort, filters and grouping. Kept per browser
 * (localStorage) and written to the URL query (a bookmark of `/?view=list&state=alarm` opens
 * that view); a query in the URL wins over what the browser kept.
 */

export const VIEWS = ['grid', 'list'] as const;
export const SORTS = ['file', 'name', 'state', 'family'] as const;
export const STATE_FILTERS = ['all', 'alarm', 'running', 'paused', 'idle', 'offline', 'unknown'] as const;
export const GROUPINGS = ['none', 'family', 'group'] as const;

export type FleetView = (typeof VIEWS)[number];
export type FleetSort = (typeof SORTS)[number];
export type StateFilter = (typeof STATE_FILTERS)[number];
export type Grouping = (typeof GROUPINGS)[number];

export interface FleetPrefs {
  view: FleetView;
  sort: FleetSort;
  state: StateFilter;
  family: MachineKind | 'all';
  /** Name filter (part of the name, any case). */
  q: string;
  groupBy: Grouping;
}

export const DEFAULT_PREFS: FleetPrefs = {
  view: 'grid',
  sort: 'file',
  state: 'all',
  family: 'all',
  q: '',
  groupBy: 'none',
};

/** A name filter longer than this is cut (a URL is not a place for essays). */
export const MAX_QUERY = 80;

/** The query parameter of each preference. */
const PARAM: Record<keyof FleetPrefs, string> = {
  view: 'view',
  sort: 'sort',
  state: 'state',
  family: 'family',
  q: 'q',
  groupBy: 'group',
};

function pick<T extends string>(allowed: readonly T[], value: unknown, fallback: T): T {
  return typeof value === 'string' && (allowed as readonly string[]).includes(value)
    ? (value as T)
    : fallback;
}

/** Any value (from a URL or storage) as preferences: unknown values are the defaults. */
export function normalizePrefs(raw: Partial<Record<keyof FleetPrefs, unknown>>): FleetPrefs {
  return {
    view: pick(VIEWS, raw.view, DEFAULT_PREFS.view),
    sort: pick(SORTS, raw.sort, DEFAULT_PREFS.sort),
    state: pick(STATE_FILTERS, raw.state, DEFAULT_PREFS.state),
    family: pick<MachineKind | 'all'>(['all', ...MACHINE_KINDS], raw.family, 'all'),
    q: typeof raw.q === 'string' ? raw.q.slice(0, MAX_QUERY) : '',
    groupBy: pick(GROUPINGS, raw.groupBy, DEFAULT_PREFS.groupBy),
  };
}

/** Whether the query says anything about the fleet view (else the browser's kept view applies). */
export function queryHasPrefs(search: string): boolean {
  const p = new URLSearchParams(search);
  return Object.values(PARAM).some((k) => p.has(k));
}

export function prefsFromQuery(search: string): FleetPrefs {
  const p = new URLSearchParams(search);
  const raw: Partial<Record<keyof FleetPrefs, unknown>> = {};
  for (const [key, param] of Object.entries(PARAM) as Array<[keyof FleetPrefs, string]>) {
    const v = p.get(param);
    if (v !== null) raw[key] = v;
  }
  return normalizePrefs(raw);
}

/** The query for these preferences ("" for the defaults), with `?` when not empty. */
export function prefsToQuery(prefs: FleetPrefs): string {
  const p = new URLSearchParams();
  for (const [key, param] of Object.entries(PARAM) as Array<[keyof FleetPrefs, string]>) {
    if (prefs[key] !== DEFAULT_PREFS[key]) p.set(param, prefs[key]);
  }
  const s = p.toString();
  return s ? `?${s}` : '';
}

export function samePrefs(a: FleetPrefs, b: FleetPrefs): boolean {
  return (Object.keys(PARAM) as Array<keyof FleetPrefs>).every((k) => a[k] === b[k]);
}

export const PREFS_KEY = 'shopdeck.fleetView';

function storage(): Storage | null {
  try {
    return typeof localStorage === 'undefined' ? null : localStorage;
  } catch {
    return null;
  }
}

export function loadStoredPrefs(): FleetPrefs {
  try {
    const text = storage()?.getItem(PREFS_KEY);
    if (!text) return DEFAULT_PREFS;
    const raw: unknown = JSON.parse(text);
    return raw && typeof raw === 'object' ? normalizePrefs(raw as Record<string, unknown>) : DEFAULT_PREFS;
  } catch {
    return DEFAULT_PREFS;
  }
}

export function storePrefs(prefs: FleetPrefs): void {
  try {
    storage()?.setItem(PREFS_KEY, JSON.stringify(prefs));
  } catch {
    // Private mode or full storage: the view still works, it is just not kept.
  }
}

/**
 * The current fleet view of this tab: the fleet page shows it, the shortcuts walk machines in
 * its order. Starts from what the browser kept; the fleet page applies a URL query over it.
 */
export const fleetPrefsStore = createStore<FleetPrefs>(() => loadStoredPrefs());

/** Changes the view, keeps it for the browser. */
export function setFleetPrefs(patch: Partial<FleetPrefs>): void {
  const next = normalizePrefs({ ...fleetPrefsStore.getState(), ...patch });
  if (samePrefs(next, fleetPrefsStore.getState())) return;
  fleetPrefsStore.setState(next, true);
  storePrefs(next);
}
