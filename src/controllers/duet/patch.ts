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
 */

export type Json = null | boolean | number | string | Json[] | JsonObject;
export interface JsonObject {
  [key: string]: Json;
}

export function isObject(v: unknown): v is JsonObject {
  return typeof v === 'object' && v !== null && !Array.isArray(v);
}

export interface PatchResult {
  model: JsonObject;
  /** `messages` entries carried by the patch, in order (raw: validated by the caller). */
  messages: Json[];
}

/** Discriminators of items whose type may change (see the header). Keyed by dotted path ('*' = any index). */
const DISCRIMINATORS: Record<string, string> = {
  'move.kinematics': 'name',
  'sensors.filamentMonitors.*': 'type',
};

/** Keys (by dotted path) that are dictionaries where `null` deletes the key. */
const NULL_DELETES = new Set(['plugins']);

/** Apply one patch to a model. Pure: neither argument is modified. */
export function applyPatch(model: JsonObject, patch: JsonObject): PatchResult {
  const messages: Json[] = [];
  const { messages: incoming, ...rest } = patch;
  if (Array.isArray(incoming)) messages.push(...incoming);
  const merged = mergeObject(model, rest, '');
  // The model never keeps messages: they were events.
  if ('messages' in merged || 'messages' in patch) merged['messages'] = [];
  return { model: merged, messages };
}

/** A full model (the first frame): the same message extraction, nothing merged. */
export function takeFullModel(full: JsonObject): PatchResult {
  return applyPatch({}, full);
}

function mergeObject(target: JsonObject, patch: JsonObject, path: string): JsonObject {
  const out: JsonObject = { ...target };
  const deletes = NULL_DELETES.has(path);
  for (const [key, value] of Object.entries(patch)) {
    const childPath = path ? `${path}.${key}` : key;
    if (value === null) {
      if (deletes) delete out[key];
      else out[key] = null;
      continue;
    }
    out[key] = mergeValue(out[key], value, childPath);
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
    const disc = DISCRIMINATORS[path];
    if (disc && disc in patch && patch[disc] !== current[disc]) return mergeObject({}, patch, path);
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
 * The inverse, for the simulator: the smallest patch (under the rules above) that turns `from`
 * into `to`, or null when nothing changed. `messages` are not diffed (they are events).
 */
export function diffModel(from: JsonObject, to: JsonObject): JsonObject | null {
  return diffObject(from, to, '');
}

function diffObject(from: JsonObject, to: JsonObject, path: string): JsonObject | null {
  const out: JsonObject = {};
  let changed = false;
  for (const [key, value] of Object.entries(to)) {
    if (!path && key === 'messages') continue;
    const childPath = path ? `${path}.${key}` : key;
    const d = diffValue(from[key], value, childPath);
    if (d !== undefined) {
      out[key] = d;
      changed = true;
    }
  }
  for (const key of Object.keys(from)) {
    if (!(key in to)) {
      // Only dictionaries can lose keys; elsewhere a vanished key is sent as null.
      out[key] = null;
      changed = true;
    }
  }
  return changed ? out : null;
}

/** undefined: unchanged. */
function diffValue(from: Json | undefined, to: Json, path: string): Json | undefined {
  if (Array.isArray(to)) {
    if (!Array.isArray(from)) return to;
    let changed = from.length !== to.length;
    const items: Json[] = to.map((item, i) => {
      const prev = from[i];
      if (isObject(item) && isObject(prev)) {
        const disc = DISCRIMINATORS[`${path}.*`];
        if (disc && item[disc] !== prev[disc]) {
          changed = true;
          return item;
        }
        const d = diffObject(prev, item, `${path}.*`);
        if (d) changed = true;
        return d ?? {};
      }
      if (!jsonEqual(prev, item)) changed = true;
      // An empty object item would read as "unchanged": send it as it is only when it is new.
      return item;
    });
    return changed ? items : undefined;
  }
  if (isObject(to)) {
    if (!isObject(from)) return to;
    const disc = DISCRIMINATORS[path];
    if (disc && to[disc] !== from[disc]) return to;
    const d = diffObject(from, to, path);
    return d ?? undefined;
  }
  return jsonEqual(from, to) ? undefined : to;
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
