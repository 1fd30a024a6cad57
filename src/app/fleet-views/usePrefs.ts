import { useCallback, useEffect, useMemo } from 'react';
import { useStore } from 'zustand';
import { useLocation } from '../router';
import {
  fleetPrefsStore,
  normalizePrefs,
  prefsFromQuery,
  prefsToQuery,
  queryHasPrefs,
  samePrefs,
  setFleetPrefs,
  type FleetPrefs,
} from './prefs';

/** Writes the view into the fleet page's URL (no history entry: a view change is not a page). */
function showInUrl(prefs: FleetPrefs): void {
  const want = prefsToQuery(prefs);
  if (location.pathname === '/' && location.search !== want)
    history.replaceState(history.state, '', `/${want}`);
}

/**
 * The fleet view in effect: the URL's query when it has one (a bookmark, back and forward), else
 * what this browser kept. `update` changes it, keeps it, and shows it in the URL.
 */
export function useFleetPrefs(): [FleetPrefs, (patch: Partial<FleetPrefs>) => void] {
  const { search } = useLocation();
  const kept = useStore(fleetPrefsStore);
  const fromUrl = useMemo(() => (queryHasPrefs(search) ? prefsFromQuery(search) : null), [search]);
  const prefs = fromUrl && !samePrefs(fromUrl, kept) ? fromUrl : kept;

  useEffect(() => {
    // The URL's view becomes the kept one (the shortcuts walk machines in its order); a URL
    // without one (the Fleet link) shows the kept view.
    if (fromUrl) setFleetPrefs(fromUrl);
    else showInUrl(fleetPrefsStore.getState());
  }, [fromUrl]);

  const update = useCallback(
    (patch: Partial<FleetPrefs>) => {
      const next = normalizePrefs({ ...prefs, ...patch });
      // URL first: the render that the store's change brings reads it.
      showInUrl(next);
      setFleetPrefs(next);
    },
    [prefs],
  );
  return [prefs, update];
}
