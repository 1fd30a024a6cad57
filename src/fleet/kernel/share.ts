import { replaceEqualDeep } from '@tanstack/query-core';
import { createStore, type StateCreator, type StoreApi } from 'zustand/vanilla';

/**
 * Structural sharing on every store write, once for the whole console: a write keeps the
 * previous object for every part that is deep-equal to what was there, so a component that
 * selects an unchanged part sees the same reference and does not re-render, and a write that
 * changes nothing notifies nobody. Plain objects and arrays are compared; anything else (a Map,
 * a class instance, a Blob) is replaced as written.
 */
export { replaceEqualDeep };

type SetState<T> = StoreApi<T>['setState'];

/** Wraps a store's `setState` with structural sharing against the current state. */
export function withSharing<T>(store: StoreApi<T>): StoreApi<T> {
  const raw = store.setState;
  const setState: SetState<T> = (partial: T | Partial<T> | ((s: T) => T | Partial<T>), replace?: boolean) => {
    const prev = store.getState();
    const next = typeof partial === 'function' ? (partial as (s: T) => T | Partial<T>)(prev) : partial;
    const merged = replace ? (next as T) : ({ ...prev, ...next } as T);
    const shared = replaceEqualDeep(prev, merged);
    if (Object.is(shared, prev)) return;
    raw(shared, true);
  };
  store.setState = setState;
  return store;
}

/** `createStore` with structural sharing on every write: what every session store uses. */
export function createSharedStore<T extends object>(initializer: StateCreator<T, [], []>): StoreApi<T> {
  const store = createStore<T>()((set, get, api) => {
    // The initializer's own `set` goes through the sharing wrapper too.
    const shared: typeof set = ((partial: Parameters<typeof set>[0], replace?: boolean) =>
      api.setState(partial as T, replace as false)) as typeof set;
    return initializer(shared, get, api);
  });
  return withSharing(store);
}
