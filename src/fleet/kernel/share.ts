import { createStore, type StateCreator, type StoreApi } from 'zustand/vanilla';

/**
 * Structural sharing on every store write, once for the whole console: a write keeps the
 * previous object for every part that is deep-equal to what was there, so a component that
 * selects an unchanged part sees the same reference and does not re-render, and a write that
 * changes nothing notifies nobody. Plain objects and arrays are compared; anything else (a Map,
 * a class instance, a Blob) is replaced as written.
 */

/*
 * `isPlainObject` and `replaceEqualDeep` below are ported from @tanstack/query-core's utils (the
 * console's query layer, kernel/query.ts, replaced that package: measured −6.5 KiB gzip on every
 * page that reads on demand, docs/performance.md). Their licence:
 *
 * MIT License. Copyright (c) 2021-present Tanner Linsley.
 * Permission is hereby granted, free of charge, to any person obtaining a copy of this software
 * and associated documentation files (the "Software"), to deal in the Software without
 * restriction, including without limitation the rights to use, copy, modify, merge, publish,
 * distribute, sublicense, and/or sell copies of the Software, and to permit persons to whom the
 * Software is furnished to do so, subject to the following conditions: The above copyright notice
 * and this permission notice shall be included in all copies or substantial portions of the
 * Software. THE SOFTWARE IS PROVIDED "AS IS", WITHOUT WARRANTY OF ANY KIND, EXPRESS OR IMPLIED,
 * INCLUDING BUT NOT LIMITED TO THE WARRANTIES OF MERCHANTABILITY, FITNESS FOR A PARTICULAR
 * PURPOSE AND NONINFRINGEMENT. IN NO EVENT SHALL THE AUTHORS OR COPYRIGHT HOLDERS BE LIABLE FOR
 * ANY CLAIM, DAMAGES OR OTHER LIABILITY, WHETHER IN AN ACTION OF CONTRACT, TORT OR OTHERWISE,
 * ARISING FROM, OUT OF OR IN CONNECTION WITH THE SOFTWARE OR THE USE OR OTHER DEALINGS IN THE
 * SOFTWARE.
 */

const hasOwn = Object.prototype.hasOwnProperty;

/** `[object Object]` by `Object.prototype.toString` (not a Date, a Map, a tagged class, …). */
function hasObjectPrototype(o: unknown): boolean {
  return Object.prototype.toString.call(o) === '[object Object]';
}

/** An object literal or `Object.create(null)`: not a class instance. */
export function isPlainObject(o: unknown): o is Record<PropertyKey, unknown> {
  if (!hasObjectPrototype(o)) return false;
  const proto: unknown = Object.getPrototypeOf(o);
  const ctor: unknown = (proto as { constructor?: unknown } | null)?.constructor;
  if (ctor === undefined) return true;
  if (typeof ctor !== 'function') return false;
  const prot: unknown = ctor.prototype;
  if (!hasObjectPrototype(prot)) return false;
  if (!hasOwn.call(prot, 'isPrototypeOf')) return false;
  return proto === Object.prototype;
}

/** An array with no holes and no extra properties. */
function isPlainArray(value: unknown): value is unknown[] {
  return Array.isArray(value) && value.length === Object.keys(value).length;
}

/**
 * `b`, with every part deep-equal to the same part of `a` replaced by `a`'s object; `a` itself
 * when all of it is equal. Only plain objects and plain arrays are walked; any other value
 * (a Map, a Date, a class instance) is taken from `b` as written unless it is the same reference.
 * An array of another length, or an object with other keys, is a new object (its equal items
 * still `a`'s); a key whose value is `undefined` counts as a key.
 */
export function replaceEqualDeep<T>(a: unknown, b: T, depth?: number): T;
export function replaceEqualDeep(a: unknown, b: unknown, depth = 0): unknown {
  if (a === b) return a;
  if (depth > 500) return b;
  const array = isPlainArray(a) && isPlainArray(b);
  if (!array && !(isPlainObject(a) && isPlainObject(b))) return b;
  const prev = a as Record<PropertyKey, unknown>;
  const next = b as Record<PropertyKey, unknown>;
  const aSize = (array ? (a as unknown[]) : Object.keys(prev)).length;
  const bItems = array ? (b as unknown[]) : Object.keys(next);
  const bSize = bItems.length;
  const copy = (array ? new Array(bSize) : {}) as Record<PropertyKey, unknown>;
  let equalItems = 0;
  for (let i = 0; i < bSize; i++) {
    const key = array ? i : (bItems[i] as string);
    const aItem = prev[key];
    const bItem = next[key];
    if (aItem === bItem) {
      copy[key] = aItem;
      if (array ? i < aSize : hasOwn.call(prev, key)) equalItems++;
      continue;
    }
    if (aItem === null || bItem === null || typeof aItem !== 'object' || typeof bItem !== 'object') {
      copy[key] = bItem;
      continue;
    }
    const v = replaceEqualDeep(aItem, bItem, depth + 1);
    copy[key] = v;
    if (v === aItem) equalItems++;
  }
  return aSize === bSize && equalItems === aSize ? a : copy;
}

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
