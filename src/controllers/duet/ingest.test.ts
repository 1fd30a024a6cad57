import { afterEach, beforeEach, describe, expect, it, vi } from 'vitest';
import { LinkTracker } from '../../fleet/contract/link-tracker';
import { createContext } from '../../fleet/fleet';
import { ModelIngest } from './ingest';
import { createDuetStore, HISTORY_POINTS } from './state';

/** A polled object model with two heaters whose temperatures change with `n`. */
const model = (n: number) => ({
  state: { status: 'idle' },
  heat: {
    heaters: [
      { current: 20 + (n % 7), active: 0, standby: 0, state: 'off' },
      { current: 60 + (n % 5), active: 60, standby: 0, state: 'active' },
    ],
  },
});

function rig(detail: { shown: boolean }) {
  const ctx = createContext(
    { id: 'dm', name: 'Duet', kind: 'duet', simulated: true },
    { detail: () => detail.shown, now: () => Date.now() },
  );
  const store = createDuetStore();
  const ingest = new ModelIngest({
    ctx,
    tracker: new LinkTracker(ctx),
    store,
    accepted: () => undefined,
    resync: () => undefined,
  });
  const points = () => Object.values(store.getState().history).reduce((s, p) => s + p.length, 0);
  /** `n` models, one a second (the history's own pace). */
  const feed = (n: number, from = 0) => {
    for (let i = 0; i < n; i++) {
      vi.advanceTimersByTime(1000);
      ingest.polled(model(from + i));
    }
  };
  return { store, points, feed };
}

beforeEach(() => {
  vi.useFakeTimers({ toFake: ['setTimeout', 'clearTimeout', 'setInterval', 'clearInterval', 'Date'] });
});
afterEach(() => {
  vi.useRealTimers();
});

describe('the Duet temperature history (heap on a fleet page)', () => {
  it('keeps no points while no page shows the machine’s details: 3000 models on a fleet page leave it empty', () => {
    const r = rig({ shown: false });
    r.feed(3000);
    expect(r.store.getState().model?.heat.heaters).toHaveLength(2);
    expect(r.points()).toBe(0);
  });

  it('records while a machine page is open (capped per heater), and lets go when it closes', () => {
    const detail = { shown: true };
    const r = rig(detail);
    r.feed(HISTORY_POINTS + 100);
    expect(r.store.getState().history[0]).toHaveLength(HISTORY_POINTS);
    expect(r.store.getState().history[1]).toHaveLength(HISTORY_POINTS);
    expect(r.points()).toBe(2 * HISTORY_POINTS);
    detail.shown = false;
    r.feed(1, 1000);
    expect(r.points()).toBe(0);
    // Opened again: the history starts over with the next model.
    detail.shown = true;
    r.feed(5, 1001);
    expect(r.store.getState().history[1]).toHaveLength(5);
  });
});
