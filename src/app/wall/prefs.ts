import { useCallback, useEffect, useMemo } from 'react';
import { useStore } from 'zustand';
import { createStore } from 'zustand/vanilla';
import type { MachineInfo } from '../../fleet/types';
import { useLocation } from '../router';

/**
 * How the wall screen groups the fleet: one grid, or one section per bay (the machines file's
 * `group`). Kept per browser (localStorage) like the fleet page's view, and set by the URL
 * (`/wall?group=bay`): a TV is configured once by the address it opens; the query wins over what
 * the browser kept, and becomes what it keeps.
 */
export const WALL_GROUPINGS = ['none', 'bay'] as const;
export type WallGrouping = (typeof WALL_GROUPINGS)[number];

export const WALL_PREFS_KEY = 'shopdeck.wallView';
/** Machines without a bay in the machines file. */
export const NO_BAY = 'No bay';

function pick(value: unknown): WallGrouping | null {
  return typeof value === 'string' && (WALL_GROUPINGS as readonly string[]).includes(value)
    ? (value as WallGrouping)
    : null;
}

/** The grouping the query names (`?group=bay`), or null when it names none (or an unknown one). */
export function groupingFromQuery(search: string): WallGrouping | null {
  return pick(new URLSearchParams(search).get('group'));
}

/** The wall's query for a grouping ("" for the default). */
export function groupingToQuery(g: WallGrouping): string {
  return g === 'none' ? '' : `?group=${g}`;
}

function storage(): Storage | null {
  try {
    return typeof localStorage === 'undefined' ? null : localStorage;
  } catch {
    return null;
  }
}

export function loadWallGrouping(): WallGrouping {
  try {
    const raw: unknown = JSON.parse(storage()?.getItem(WALL_PREFS_KEY) ?? 'null');
    const g = raw !== null && typeof raw === 'object' ? pick((raw as { groupBy?: unknown }).groupBy) : null;
    return g ?? 'none';
  } catch {
    return 'none';
  }
}

function storeWallGrouping(g: WallGrouping): void {
  try {
    storage()?.setItem(WALL_PREFS_KEY, JSON.stringify({ groupBy: g }));
  } catch {
    // Private mode or full storage: the wall still groups, it is just not kept.
  }
}

export const wallPrefsStore = createStore<{ groupBy: WallGrouping }>(() => ({ groupBy: loadWallGrouping() }));

export function setWallGrouping(g: WallGrouping): void {
  if (wallPrefsStore.getState().groupBy !== g) wallPrefsStore.setState({ groupBy: g });
  storeWallGrouping(g);
}

/** Writes the grouping into the wall's URL (no history entry: a view is not a page). */
function showInUrl(g: WallGrouping): void {
  const want = groupingToQuery(g);
  if (location.pathname === '/wall' && location.search !== want)
    history.replaceState(history.state, '', `/wall${want}`);
}

/** The wall's grouping in effect (the URL's, else the kept one) and its setter. */
export function useWallGrouping(): [WallGrouping, (g: WallGrouping) => void] {
  const { search } = useLocation();
  const kept = useStore(wallPrefsStore, (s) => s.groupBy);
  const fromUrl = useMemo(() => groupingFromQuery(search), [search]);
  useEffect(() => {
    if (fromUrl) setWallGrouping(fromUrl);
    else showInUrl(wallPrefsStore.getState().groupBy);
  }, [fromUrl]);
  const update = useCallback((g: WallGrouping) => {
    // URL first: the render that the store's change brings reads it.
    showInUrl(g);
    setWallGrouping(g);
  }, []);
  return [fromUrl ?? kept, update];
}

export interface WallSection {
  /** The bay's name ("" for the machines without one). */
  key: string;
  label: string;
  machines: MachineInfo[];
}

const collator = new Intl.Collator(undefined, { numeric: true, sensitivity: 'base' });

/** One section per bay, bays by name, fleet order within a bay, the machines without one last. */
export function wallSections(machines: readonly MachineInfo[]): WallSection[] {
  const byBay = new Map<string, WallSection>();
  for (const m of machines) {
    const key = m.group ?? '';
    let s = byBay.get(key);
    if (!s) {
      s = { key, label: key || NO_BAY, machines: [] };
      byBay.set(key, s);
    }
    s.machines.push(m);
  }
  return [...byBay.values()].sort(
    (a, b) => Number(a.key === '') - Number(b.key === '') || collator.compare(a.key, b.key),
  );
}

/** Where a section sits in the wall's grid (1-based lines), and the rows of the grid. */
export interface SectionPlace {
  column: number;
  /** Columns it spans. */
  columns: number;
  /** Its heading's row; its cards' rows follow. */
  row: number;
  /** Rows of cards. */
  rows: number;
}

export interface SectionLayout {
  columns: number;
  places: SectionPlace[];
  /** `grid-template-rows`: per shelf of sections, a row for the headings, then the card rows. */
  rowsTemplate: string;
}

/**
 * Sections of `sizes` cards laid out in one grid of `cols` columns: in order, side by side while
 * they fit in a row (a small bay beside another), each as wide as its cards (at most the grid).
 */
function shelve(sizes: readonly number[], cols: number): { places: SectionPlace[]; shelves: number[] } {
  const places: SectionPlace[] = [];
  const shelves: number[] = [];
  let used = cols;
  let row = 1;
  for (const n of sizes) {
    const columns = Math.min(Math.max(n, 1), cols);
    const rows = Math.ceil(Math.max(n, 1) / cols);
    if (used + columns > cols) {
      if (shelves.length > 0) row += 1 + (shelves[shelves.length - 1] ?? 0);
      shelves.push(0);
      used = 0;
    }
    places.push({ column: used + 1, columns, row, rows });
    shelves[shelves.length - 1] = Math.max(shelves[shelves.length - 1] ?? 0, rows);
    used += columns;
  }
  return { places, shelves };
}

/**
 * The wall grouped by bay on an area `aspect` (width / height) times as wide as high, each shelf's
 * headings taking about `heading` of the height: the column count whose cells hold the largest
 * card of about 1.5:1 (as `wallColumns` for the one grid).
 */
export function wallSectionLayout(sizes: readonly number[], aspect: number, heading = 0.05): SectionLayout {
  const total = sizes.reduce((a, b) => a + b, 0);
  let best: { cols: number; size: number; shelves: number[]; places: SectionPlace[] } | null = null;
  for (let cols = 1; cols <= Math.max(1, total); cols++) {
    const { places, shelves } = shelve(sizes, cols);
    const rows = shelves.reduce((a, b) => a + b, 0);
    const height = Math.max(0.2, 1 - heading * shelves.length);
    // The card's width in units of the area's height: the cell's, or what its height allows.
    const size = Math.min(aspect / cols, (1.5 * height) / rows);
    if (!best || size > best.size + 1e-9) best = { cols, size, shelves, places };
  }
  const b = best ?? { cols: 1, shelves: [], places: [] };
  return {
    columns: b.cols,
    places: b.places,
    rowsTemplate: b.shelves.map((h) => `auto repeat(${h}, minmax(0, 1fr))`).join(' '),
  };
}
