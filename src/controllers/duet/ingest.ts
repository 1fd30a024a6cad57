import type { StoreApi } from 'zustand/vanilla';
import type { LinkTracker, SessionContext } from '../../fleet/contract';
import { LinkError } from '../../fleet/errors';
import { DuetModel, type ModelUpdate } from './model';
import { isObject, type Json, type JsonObject } from './patch';
import { snapshotOf } from './snapshot';
import { HISTORY_EVERY_MS, withHistoryPoint, type DuetState } from './state';
import { messageLevel, messageSchema, type ObjectModel } from './wire';

/**
 * What arrives from the machine, into the console: socket frames and polled models become the
 * object model (`model.ts`), the machine snapshot (`snapshot.ts`), the temperature history and
 * the machine log (`messages`). The session decides when (its run, its socket); this decides
 * what is written.
 */
export interface IngestHost {
  ctx: SessionContext;
  tracker: LinkTracker;
  store: StoreApi<DuetState>;
  /** A valid model arrived (the session's silent re-login may be tried again). */
  accepted(): void;
  /**
   * A socket frame was dropped (unreadable, or a patch refused): the model may now differ from
   * the machine's, which is read whole again (the session decides when).
   */
  resync(): void;
}

export class ModelIngest {
  private readonly model = new DuetModel();
  /** Messages already logged from a polled model (a polled model may repeat them). */
  private polledMessages = new Set<string>();
  private readonly alarmSince = new Map<string, number>();
  private lastHistoryAt = 0;

  constructor(private readonly h: IngestHost) {}

  /**
   * A socket frame: its object, `pong`, or null when it was no object (shown as a protocol error
   * and dropped; the model is read again).
   */
  parse(data: string): JsonObject | 'pong' | null {
    const text = data.trim();
    if (text === 'PONG') return 'pong';
    let parsed: unknown;
    try {
      parsed = JSON.parse(text);
    } catch {
      this.dropped(
        new LinkError('protocol', `WS /machine: a frame that is not JSON (${text.slice(0, 60)})`, {
          path: '(root)',
        }),
      );
      return null;
    }
    if (isObject(parsed)) return parsed;
    this.dropped(new LinkError('protocol', 'WS /machine: a frame that is not an object', { path: '(root)' }));
    return null;
  }

  /** A socket frame: the full model (`full`, a socket's first frame) or a patch. */
  frame(frame: JsonObject, full: boolean): void {
    const r = full ? this.model.full(frame) : this.model.patch(frame);
    for (const m of r.messages) this.logMessage(m);
    if (!r.ok && r.dropped) this.dropped(r.error);
    else this.accept(r);
  }

  /** A frame that was dropped: the error on screen and in the log, and the model read again. */
  private dropped(e: LinkError): void {
    this.h.tracker.fail(
      new LinkError('protocol', `${e.message} (dropped; the object model is read again)`, {
        path: e.path ?? '(root)',
      }),
    );
    this.h.resync();
  }

  /** The socket delivers again: polled messages are forgotten. */
  socketBack(): void {
    this.polledMessages.clear();
  }

  /** A model from `GET /machine/model`: its messages are logged once, however often polled. */
  polled(raw: JsonObject): void {
    const r = this.model.full(raw);
    const seen = new Set<string>();
    for (const m of r.messages) {
      const k = JSON.stringify(m);
      seen.add(k);
      if (!this.polledMessages.has(k)) this.logMessage(m);
    }
    this.polledMessages = seen;
    this.accept(r);
  }

  private logMessage(m: Json): void {
    const p = messageSchema.safeParse(m);
    if (!p.success) return;
    const at = p.data.time ? Date.parse(p.data.time) : NaN;
    this.h.ctx.log.add(
      messageLevel(p.data.type),
      'controller',
      p.data.content,
      Number.isNaN(at) ? undefined : at,
    );
  }

  private accept(r: ModelUpdate): void {
    if (!r.ok) {
      this.h.tracker.fail(r.error);
      return;
    }
    this.acceptModel(r.model);
  }

  private acceptModel(m: ObjectModel): void {
    const now = this.h.ctx.now();
    this.h.accepted();
    const since = (id: string): number => {
      const t = this.alarmSince.get(id);
      if (t !== undefined) return t;
      this.alarmSince.set(id, now);
      return now;
    };
    const snap = snapshotOf(m, since);
    const live = new Set((snap.alarms ?? []).map((a) => a.id));
    for (const id of [...this.alarmSince.keys()]) if (!live.has(id)) this.alarmSince.delete(id);
    this.h.tracker.ok(snap);
    const patch: Partial<DuetState> = { model: m, needsPassword: false };
    // The chart's history only while a page shows the machine's details: a fleet page of 20 Duets
    // would otherwise fill 15 minutes of points per heater it never draws (the heap's slow rise,
    // docs/performance.md). An opened chart starts with the server's last minutes instead.
    if (!this.h.ctx.detail()) {
      if (Object.keys(this.h.store.getState().history).length) patch.history = {};
      this.lastHistoryAt = 0;
    } else if (now - this.lastHistoryAt >= HISTORY_EVERY_MS) {
      this.lastHistoryAt = now;
      patch.history = withHistoryPoint(this.h.store.getState().history, m, now);
    }
    this.h.store.setState(patch);
  }
}
