import { describe, expect, it } from 'vitest';
import { replaceEqualDeep } from './share';

/** Structural sharing (share.ts): which parts keep the previous objects. */

describe('replaceEqualDeep', () => {
  it('returns the previous value itself when all of it is deep-equal', () => {
    const prev = { a: { b: [1, { c: 'x' }] }, n: null, s: 's' };
    expect(replaceEqualDeep(prev, structuredClone(prev))).toBe(prev);
    const list = [{ id: 1 }, { id: 2 }];
    expect(replaceEqualDeep(list, structuredClone(list))).toBe(list);
    expect(replaceEqualDeep(1, 1)).toBe(1);
    expect(replaceEqualDeep(NaN, NaN)).toBeNaN();
  });

  it('keeps the equal parts of a changed value and takes the rest as written', () => {
    const prev = { a: { x: 1 }, b: { y: [1, 2] }, c: [{ id: 1 }, { id: 2 }] };
    const next = { a: { x: 1 }, b: { y: [1, 3] }, c: [{ id: 1 }, { id: 3 }] };
    const out = replaceEqualDeep(prev, next);
    expect(out).toEqual(next);
    expect(out).not.toBe(prev);
    expect(out).not.toBe(next);
    expect(out.a).toBe(prev.a);
    expect(out.b).not.toBe(prev.b);
    expect(out.c[0]).toBe(prev.c[0]);
    // A changed plain object is a new copy (neither the previous nor the written object).
    expect(out.c[1]).toEqual({ id: 3 });
    expect(out.c[1]).not.toBe(prev.c[1]);
    expect(out.c[1]).not.toBe(next.c[1]);
  });

  it('an array of another length is a new array; its equal items are the previous ones', () => {
    const a = { id: 1 };
    const b = { id: 2 };
    const longer = replaceEqualDeep([a], [{ id: 1 }, { id: 2 }]);
    expect(longer).toEqual([a, b]);
    expect(longer[0]).toBe(a);
    const prev = [a, b];
    const shorter = replaceEqualDeep(prev, [{ id: 1 }]);
    expect(shorter).not.toBe(prev);
    expect(shorter).toEqual([a]);
    expect(shorter[0]).toBe(a);
  });

  it('a key whose value is undefined counts as a key', () => {
    const prev = { a: 1 };
    const withUndefined = replaceEqualDeep(prev, { a: 1, b: undefined });
    expect(withUndefined).not.toBe(prev);
    expect(Object.keys(withUndefined)).toEqual(['a', 'b']);
    const prev2: Record<string, number | undefined> = { a: 1, b: undefined };
    const without = replaceEqualDeep(prev2, { a: 1 });
    expect(without).not.toBe(prev2);
    expect(Object.keys(without)).toEqual(['a']);
    // Same count of keys, one renamed: not equal.
    const renamed = replaceEqualDeep<Record<string, number | undefined>>(prev2, { a: 1, c: undefined });
    expect(renamed).not.toBe(prev2);
    expect(Object.keys(renamed)).toEqual(['a', 'c']);
    // Same keys, both undefined: equal.
    expect(replaceEqualDeep(prev2, { a: 1, b: undefined })).toBe(prev2);
  });

  it('anything not a plain object or array is replaced as written, even when equal', () => {
    const d = new Date(0);
    const next = new Date(0);
    expect(replaceEqualDeep(d, next)).toBe(next);
    const m = new Map([[1, 2]]);
    const m2 = new Map([[1, 2]]);
    expect(replaceEqualDeep({ m }, { m: m2 }).m).toBe(m2);
    class Point {
      constructor(readonly x: number) {}
    }
    const p = new Point(1);
    const p2 = new Point(1);
    expect(replaceEqualDeep([p], [p2])[0]).toBe(p2);
    // The same reference is kept, plain or not.
    const prev = { p, at: d };
    expect(replaceEqualDeep(prev, { p, at: d })).toBe(prev);
    // An array with extra properties or holes is not plain.
    const holes: unknown[] = Object.assign(new Array(3), { 0: 1, 2: 3 });
    const holes2: unknown[] = Object.assign(new Array(3), { 0: 1, 2: 3 });
    expect(replaceEqualDeep(holes, holes2)).toBe(holes2);
    const tagged = Object.assign([1], { extra: true });
    const tagged2 = Object.assign([1], { extra: true });
    expect(replaceEqualDeep(tagged, tagged2)).toBe(tagged2);
    // A plain object against an array (or the reverse) is replaced.
    const arr: unknown = [];
    expect(replaceEqualDeep({}, arr)).toBe(arr);
  });

  it('an object without prototype is plain', () => {
    const prev = Object.assign(Object.create(null) as Record<string, unknown>, { a: { b: 1 } });
    const next = Object.assign(Object.create(null) as Record<string, unknown>, { a: { b: 1 } });
    expect(replaceEqualDeep(prev, next)).toBe(prev);
  });

  it('null, undefined and primitives against objects take the new value', () => {
    const prev = { a: { x: 1 }, b: null as { y: number } | null, c: 1 as number | { z: number } };
    const out = replaceEqualDeep(prev, { a: { x: 1 }, b: { y: 1 }, c: { z: 1 } });
    expect(out.a).toBe(prev.a);
    expect(out.b).toEqual({ y: 1 });
    expect(out.c).toEqual({ z: 1 });
    const obj = { a: 1 };
    expect(replaceEqualDeep(obj, null)).toBeNull();
    expect(replaceEqualDeep(undefined, obj)).toBe(obj);
  });
});
