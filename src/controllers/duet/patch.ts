/**
 * DSF object-model patches (the frames after the first on `WS /machine`). They are NOT RFC 7386
 * merge patches nor RFC 6902 JSON patches. The rules, as DuetWebServer / dsf-python apply them:
 *
 * - a key missing from the patch is unchanged; objects merge recursively; `null` sets null;
 * - an array's length in the patch is authoritative (longer arrays grow, shorter ones shrink);
 *   object items merge by index, `{}` means "this item is unchanged", `null` items are holes,
 *   anything else replaces the item;
 * - `plugins` is a dictionary: a key set to `null` deletes that plugin;
 * - `messages` is an append-only event list: its entries are handed back to the caller (they go
 *   to the machine's console log) and never kept in the model.
 *
 * Decision (the document is silent; this is what DSF's typed model does): some items change type
 * — `move.kinematics` (discriminated by `name`) and `sensors.filamentMonitors[]` (by `type`). DSF
 * then builds a fresh object of the new class, so keys of the old type disappear; we do the same
 * by replacing instead of merging when the discriminator in the patch differs.
 *
 * Every byte is untrusted (issue 15): a frame nested deeper than `MAX_DEPTH` is refused whole
 * (checked without recursion, before anything is merged), and the keys `__proto__`, `constructor`
 * and `prototype` are never merged (DSF's model has none; an assigned `__proto__` would become a
 * prototype).
 */

export type Json = null | boolean | number | string | Json[] | JsonObject;
export interface JsonObject {
  [key: string]: Json;
}

export function isObject(v: unknown): v is JsonObject {
  return typeof v === 'object' && v !== null && !Array.isArray(v);
}

export interface PatchResult {
  /** The merged model; when `refused`, the model as it was. */
  model: JsonObject;
  /** `messages` entries carried by the patch, in order (raw: validated by the caller). */
  messages: Json[];
  /** Why the frame was refused whole (nothing merged), or null. */
  refused: string | null;
}

/** Nesting a frame may have (DSF's models nest about 6 deep; plugin data a little more). */
export const MAX_DEPTH = 64;

/** Keys never merged: an assignment of `__proto__` changes a prototype; the others are no model's. */
const UNSAFE_KEYS: ReadonlySet<string> = new Set(['__proto__', 'constructor', 'prototype']);

export function isUnsafeKey(key: string): boolean {
  return UNSAFE_KEYS.has(key);
}

/** Whether `v` nests deeper than `limit` (iterative: a payload deeper than the stack is fine). */
export function nestsDeeper(v: Json, limit: number): boolean {
  const stack: Array<{ v: Json; d: number }> = [{ v, d: 0 }];
  for (let item = stack.pop(); item; item = stack.pop()) {
    const x = item.v;
    if (typeof x !== 'object' || x === null) continue;
    const d = item.d + 1;
    if (d > limit) return true;
    if (Array.isArray(x)) for (const c of x) stack.push({ v: c, d });
    else for (const k of Object.keys(x)) stack.push({ v: x[k] as Json, d });
  }
  return false;
}

/** Discriminators of items whose type may change (see the header). Keyed by dotted path ('*' = any index). */
const DISCRIMINATORS: Record<string, string> = {
  'move.kinematics': 'name',
  'sensors.filamentMonitors.*': 'type',
};

function discriminator(path: string): string | undefined {
  return Object.hasOwn(DISCRIMINATORS, path) ? DISCRIMINATORS[path] : undefined;
}

/** Keys (by dotted path) that are dictionaries where `null` deletes the key. */
const NULL_DELETES = new Set(['plugins']);

/** Apply one patch to a model. Pure: neither argument is modified. */
export function applyPatch(model: JsonObject, patch: JsonObject): PatchResult {
  if (nestsDeeper(patch, MAX_DEPTH))
    return { model, messages: [], refused: `a frame nested deeper than ${MAX_DEPTH} levels` };
  const messages: Json[] = [];
  const incoming = Object.hasOwn(patch, 'messages') ? patch['messages'] : undefined;
  if (Array.isArray(incoming)) messages.push(...incoming);
  const merged = mergeObject(model, patch, '');
  // The model never keeps messages: they were events.
  if (Object.hasOwn(merged, 'messages') || Object.hasOwn(patch, 'messages')) merged['messages'] = [];
  return { model: merged, messages, refused: null };
}

/** A full model (the first frame): the same message extraction, nothing merged. */
export function takeFullModel(full: JsonObject): PatchResult {
  return applyPatch({}, full);
}

function mergeObject(target: JsonObject, patch: JsonObject, path: string): JsonObject {
  const out: JsonObject = { ...target };
  const deletes = NULL_DELETES.has(path);
  for (const [key, value] of Object.entries(patch)) {
    if (UNSAFE_KEYS.has(key) || (path === '' && key === 'messages')) continue;
    const childPath = path ? `${path}.${key}` : key;
    if (value === null) {
      if (deletes) delete out[key];
      else out[key] = null;
      continue;
    }
    out[key] = mergeValue(Object.hasOwn(out, key) ? out[key] : undefined, value, childPath);
  }
  return out;
}

function mergeValue(current: Json | undefined, patch: Json, path: string): Json {
  if (Array.isArray(patch)) {
    const cur = Array.isArray(current) ? current : [];
    return patch.map((item, i) => mergeItem(cur[i], item, `${path}.*`));
  }
  if (isObject(patch)) {
    if (!isObject(current)) return mergeObject({}, patch, path);
    const disc = discriminator(path);
    if (disc && Object.hasOwn(patch, disc) && patch[disc] !== current[disc])
      return mergeObject({}, patch, path);
    return mergeObject(current, patch, path);
  }
  return patch;
}

function mergeItem(current: Json | undefined, item: Json, path: string): Json {
  if (item === null) return null;
  if (isObject(item) && Object.keys(item).length === 0) return current === undefined ? {} : current;
  return mergeValue(current, item, path);
}

/**
 * The inverse: a patch (under the rules above) that turns `from` into `to`, or null when nothing
 * changed. `messages` are not diffed (they are events; `patchBetween` carries them). Used by the
 * simulator (one patch per acknowledgement) and by the gateway's shared `WS /machine` (one patch
 * covering everything a slow browser missed, `sharing.ts`).
 *
 * Structural sharing is exploited: a subtree of `to` that is the same object as in `from` (what
 * `applyPatch` keeps for everything a patch did not touch) is skipped without being walked, so a
 * diff costs what changed, not the size of the model.
 *
 * Arrays follow DSF: the patch's length is authoritative; an object item that did not change is
 * `{}`; a changed object item carries only its changed keys; other items are sent as they are.
 * An item or value whose discriminator changed (`move.kinematics.name`,
 * `sensors.filamentMonitors[].type`) is sent whole, which makes `applyPatch` replace it.
 *
 * Limits (DSF's patches cannot say these; its typed model never produces them, only a coalesced
 * diff over several DSF patches could): a key that vanished from an object that merges (anything
 * but `plugins` and a replaced discriminated object) is sent as `null`, so the result has that key
 * set to `null` instead of missing (after an array shrank and grew again with different items, a
 * discriminated object went A → B → A, or a plugin went and came back with other keys); `{}` as an array item over an item that is not an
 * object cannot be said (`{}` reads "unchanged"); a `null` plugin value reads "delete".
 * `applyPatch(from, diffModel(from, to))` equals `to` in every other case.
 */
export function diffModel(from: JsonObject, to: JsonObject): JsonObject | null {
  return from === to ? null : diffObject(from, to, '');
}

/**
 * One patch frame that takes `from` to `to` and carries `events` as its `messages` (the model
 * itself keeps `messages: []` once it has seen any: that key is sent when `to` has it and `from`
 * has not). Always an object (`{}`: nothing changed).
 */
export function patchBetween(from: JsonObject, to: JsonObject, events: readonly Json[]): JsonObject {
  const patch = diffModel(from, to) ?? {};
  if (events.length > 0 || (Object.hasOwn(to, 'messages') && !Object.hasOwn(from, 'messages')))
    setKey(patch, 'messages', [...events]);
  return patch;
}

/** Sets an own key, even "__proto__" (a plain assignment would change the prototype). */
function setKey(o: JsonObject, key: string, value: Json): void {
  Object.defineProperty(o, key, { value, enumerable: true, writable: true, configurable: true });
}

function childPath(path: string, key: string): string {
  return path ? `${path}.${key}` : key;
}

/** `applyPatch` builds a fresh object for `to` instead of merging (its discriminator changed). */
function replaces(from: JsonObject, to: JsonObject, path: string): boolean {
  const disc = discriminator(path);
  return disc !== undefined && Object.hasOwn(to, disc) && to[disc] !== from[disc];
}

function diffObject(from: JsonObject, to: JsonObject, path: string): JsonObject | null {
  const out: JsonObject = {};
  let changed = false;
  const root = path === '';
  for (const key of Object.keys(to)) {
    if (root && key === 'messages') continue;
    const d = diffValue(
      Object.hasOwn(from, key) ? from[key] : undefined,
      to[key] as Json,
      childPath(path, key),
    );
    if (d !== undefined) {
      setKey(out, key, d);
      changed = true;
    }
  }
  for (const key of Object.keys(from)) {
    if ((root && key === 'messages') || Object.hasOwn(to, key)) continue;
    // Deletes a plugin; elsewhere DSF has no removal: null is the closest it can say (see above).
    setKey(out, key, null);
    changed = true;
  }
  return changed ? out : null;
}

/** The patch value under an object key; undefined: unchanged (the key is left out). */
function diffValue(from: Json | undefined, to: Json, path: string): Json | undefined {
  if (from === to) return undefined;
  if (Array.isArray(to)) {
    const d = diffArray(from, to, path);
    return d.changed ? d.patch : undefined;
  }
  if (isObject(to)) {
    // Built afresh from the patch alone: the whole object reproduces itself exactly.
    if (!isObject(from) || replaces(from, to, path)) return to;
    return diffObject(from, to, path) ?? undefined;
  }
  return to;
}

interface ItemDiff {
  patch: Json;
  changed: boolean;
}

/** An array patch: always every item (the length is authoritative), `changed` when any differs. */
function diffArray(from: Json | undefined, to: Json[], path: string): { patch: Json[]; changed: boolean } {
  const prev = Array.isArray(from) ? from : [];
  let changed = !Array.isArray(from) || from.length !== to.length;
  const itemPath = `${path}.*`;
  const patch = to.map((item, i) => {
    const d = diffItem(i < prev.length ? prev[i] : undefined, item, itemPath);
    if (d.changed) changed = true;
    return d.patch;
  });
  return { patch, changed };
}

/** One array item as `mergeItem` reads it. */
function diffItem(cur: Json | undefined, item: Json, path: string): ItemDiff {
  if (item === null) return { patch: null, changed: cur !== null };
  if (Array.isArray(item)) return diffArray(cur, item, path);
  if (isObject(item)) {
    if (isObject(cur)) {
      if (cur === item) return { patch: {}, changed: false };
      if (replaces(cur, item, path)) return { patch: item, changed: true };
      const d = diffObject(cur, item, path);
      return d ? { patch: d, changed: true } : { patch: {}, changed: false };
    }
    // A new item (or one that was no object) is built from the patch alone. `{}` over an item
    // that is no object reads "unchanged": a limit (see diffModel).
    return { patch: item, changed: true };
  }
  return { patch: item, changed: cur !== item };
}

export function jsonEqual(a: Json | undefined, b: Json | undefined): boolean {
  if (a === b) return true;
  if (a === undefined || b === undefined || a === null || b === null) return false;
  if (Array.isArray(a)) {
    if (!Array.isArray(b) || a.length !== b.length) return false;
    return a.every((x, i) => jsonEqual(x, b[i]));
  }
  if (isObject(a)) {
    if (!isObject(b)) return false;
    const ka = Object.keys(a);
    if (ka.length !== Object.keys(b).length) return false;
    return ka.every((k) => k in b && jsonEqual(a[k], b[k]));
  }
  return false;
}

export function cloneJson<T extends Json>(v: T): T {
  return structuredClone(v);
}
