// @vitest-environment happy-dom
import { afterEach, describe, expect, it } from 'vitest';
import {
  DEFAULT_PREFS,
  fleetPrefsStore,
  loadStoredPrefs,
  normalizePrefs,
  PREFS_KEY,
  prefsFromQuery,
  prefsToQuery,
  queryHasPrefs,
  setFleetPrefs,
} from './prefs';

afterEach(() => {
  localStorage.clear();
  fleetPrefsStore.setState(DEFAULT_PREFS, true);
});

describe('fleet view preferences', () => {
  it('round-trip through the URL query, leaving defaults out', () => {
    expect(prefsToQuery(DEFAULT_PREFS)).toBe('');
    const prefs = {
      ...DEFAULT_PREFS,
      view: 'list',
      sort: 'state',
      family: 'xtool',
      q: 'bay 2',
      groupBy: 'group',
    } as const;
    const q = prefsToQuery(prefs);
    expect(q).toBe('?view=list&sort=state&family=xtool&q=bay+2&group=group');
    expect(queryHasPrefs(q)).toBe(true);
    expect(prefsFromQuery(q)).toEqual(prefs);
    expect(queryHasPrefs('?tab=files')).toBe(false);
  });

  it('turn unknown values into the defaults and cut a long name filter', () => {
    expect(prefsFromQuery('?view=cards&sort=colour&state=burning&family=toaster&group=planet')).toEqual(
      DEFAULT_PREFS,
    );
    expect(normalizePrefs({ q: 'x'.repeat(500), view: 7 }).q).toHaveLength(80);
    expect(normalizePrefs({ view: 7 }).view).toBe('grid');
  });

  it('are kept in this browser, and a broken stored value is the defaults', () => {
    setFleetPrefs({ view: 'list', state: 'alarm' });
    expect(fleetPrefsStore.getState()).toMatchObject({ view: 'list', state: 'alarm' });
    expect(loadStoredPrefs()).toMatchObject({ view: 'list', state: 'alarm', sort: 'file' });
    localStorage.setItem(PREFS_KEY, '{not json');
    expect(loadStoredPrefs()).toEqual(DEFAULT_PREFS);
    localStorage.setItem(PREFS_KEY, JSON.stringify({ view: 'list', groupBy: '<script>' }));
    expect(loadStoredPrefs()).toEqual({ ...DEFAULT_PREFS, view: 'list' });
  });
});
