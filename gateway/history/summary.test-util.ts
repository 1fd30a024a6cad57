import type { WatchSummary } from '../../src/fleet/contract';

/** A watch summary in `state` (no alarm, no job) with `more` on top: what the watch feeds the history. */
export const S = (state: WatchSummary['state'], more: Partial<WatchSummary> = {}): WatchSummary => ({
  state,
  alarm: null,
  job: null,
  ...more,
});
