import { LinkError, protocolError } from '../../fleet/errors';
import { replaceEqualDeep } from '../../fleet/kernel';
import { applyPatch, isUnsafeKey, takeFullModel, type Json, type JsonObject } from './patch';
import { objectModelSchema, type ObjectModel } from './wire';

/**
 * The object model as the session keeps it: the raw JSON (DSF's patches apply to it, see
 * `patch.ts`) and the validated model the views read. A patch re-validates only the top-level
 * parts it touches (`heat`, `job`, `move`, …); every other part is the previous object, and inside
 * a touched part every deep-equal piece keeps its previous object too. A panel that selects an
 * unchanged part (the board, the volumes) therefore sees the same reference on every frame and
 * does not re-render, and a 24 KB model is no longer re-parsed 4 times a second.
 *
 * A patch that cannot be applied (nested beyond `MAX_DEPTH`) or that would make a valid model
 * invalid is dropped: the model stays the last valid one, and the update says `dropped` (the
 * model may now differ from the machine's: the session reads it whole again). Over a model that is
 * already invalid, patches merge as they come (the machine may be correcting it).
 */

export type ModelUpdate =
  | { ok: true; model: ObjectModel; messages: Json[] }
  | { ok: false; error: LinkError; messages: Json[]; dropped: boolean };

const WHERE = 'WS /machine (object model)';

function refusedError(why: string): LinkError {
  return new LinkError('protocol', `Unexpected answer from ${WHERE}: ${why}`, { path: '(root)' });
}

type Shape = typeof objectModelSchema.shape;
type Part = keyof Shape;
const SHAPE: Shape = objectModelSchema.shape;

function isPart(key: string): key is Part {
  return Object.hasOwn(SHAPE, key);
}

export class DuetModel {
  private raw: JsonObject | null = null;
  private parsed: ObjectModel | null = null;

  /** The current validated model (null before the first, or after an invalid one). */
  get current(): ObjectModel | null {
    return this.parsed;
  }

  /** Forget everything (a new socket sends a full model first). */
  reset(): void {
    this.raw = null;
    this.parsed = null;
  }

  /** A full model: the first frame of a socket, or `GET /machine/model`. */
  full(frame: JsonObject): ModelUpdate {
    const r = takeFullModel(frame);
    if (r.refused !== null) {
      this.reset();
      return { ok: false, error: refusedError(r.refused), messages: [], dropped: true };
    }
    this.raw = r.model;
    return this.validate(null, r.messages);
  }

  /** A patch (any frame after the first). Without a model yet it is taken as a full model. */
  patch(frame: JsonObject): ModelUpdate {
    if (!this.raw) return this.full(frame);
    const r = applyPatch(this.raw, frame);
    if (r.refused !== null) return { ok: false, error: refusedError(r.refused), messages: [], dropped: true };
    const before = { raw: this.raw, parsed: this.parsed };
    this.raw = r.model;
    const touched = Object.keys(frame).filter((k) => k !== 'messages' && !isUnsafeKey(k));
    const u = this.validate(touched, r.messages);
    if (u.ok || before.parsed === null) return u;
    // It would break a valid model: dropped, the last valid model stays.
    this.raw = before.raw;
    this.parsed = before.parsed;
    return { ...u, dropped: true };
  }

  /**
   * Validates the parts named by `touched` (all of them when null or when there is no valid
   * model yet) and keeps the previous objects for the rest.
   */
  private validate(touched: string[] | null, messages: Json[]): ModelUpdate {
    const raw = this.raw ?? {};
    const prev = this.parsed;
    if (!prev || touched === null) return this.whole(raw, prev, messages);
    const next: Record<string, unknown> = { ...prev };
    for (const key of touched) {
      if (!isPart(key)) {
        // An unknown part passes through as it is (the schema is loose).
        if (Object.hasOwn(raw, key)) next[key] = raw[key];
        else delete next[key];
        continue;
      }
      const p = SHAPE[key].safeParse(raw[key]);
      // Report the failure with the path of a whole-model parse (same words as before).
      if (!p.success) return this.whole(raw, null, messages);
      next[key] = replaceEqualDeep(prev[key], p.data);
    }
    const model = next as ObjectModel;
    this.parsed = model;
    return { ok: true, model, messages };
  }

  private whole(raw: JsonObject, prev: ObjectModel | null, messages: Json[]): ModelUpdate {
    const p = objectModelSchema.safeParse(raw);
    if (!p.success) {
      this.parsed = null;
      return { ok: false, error: protocolError(WHERE, p.error), messages, dropped: false };
    }
    const model = prev ? replaceEqualDeep(prev, p.data) : p.data;
    this.parsed = model;
    return { ok: true, model, messages };
  }
}
