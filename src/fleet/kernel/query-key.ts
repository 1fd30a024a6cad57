import { isPlainObject } from './share';

/** A read's key: `[machineId, …parts]` (MachineQueries.key). */
export type QueryKey = readonly unknown[];

export function isValidTimeout(ms: unknown): ms is number {
  return typeof ms === 'number' && ms >= 0 && ms !== Infinity;
}

/** A stable string for a key: plain objects with their keys sorted. */
export function hashKey(key: QueryKey): string {
  return JSON.stringify(key, (_, val: unknown) =>
    isPlainObject(val)
      ? Object.keys(val)
          .sort()
          .reduce<Record<string, unknown>>((out, k) => {
            out[k] = val[k];
            return out;
          }, {})
      : val,
  );
}

/** `b` is a prefix of `a` (arrays item by item, objects key by key, deeply). */
export function partialMatchKey(a: unknown, b: unknown): boolean {
  if (a === b) return true;
  if (typeof a !== typeof b) return false;
  if (a && b && typeof a === 'object' && typeof b === 'object') {
    if (Array.isArray(a) && Array.isArray(b)) {
      if (b.length > a.length) return false;
      return b.every((item, i) => partialMatchKey(a[i], item));
    }
    const x = a as Record<string, unknown>;
    const y = b as Record<string, unknown>;
    return Object.keys(y).every((k) => partialMatchKey(x[k], y[k]));
  }
  return false;
}
