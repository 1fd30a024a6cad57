/**
 * Fleet scale: how the snapshot stores and tile selectors behave with many machines.
 * A tile subscribes to its own machine only, so one machine's update costs the same whether
 * the fleet has 10 or 500 machines; this measures that ratio.
 */
import { shallow } from 'zustand/shallow';
import { createContext } from '../../src/fleet/fleet';
import { alwaysVisible } from '../../src/fleet/link';
import type { MachineSnapshot } from '../../src/fleet/types';
import { heapMiB, measure, report, round } from './util';

const select = (x: MachineSnapshot) => ({
  link: x.link,
  activity: x.activity,
  activityLabel: x.activityLabel,
  job: x.job,
  alarms: x.alarms,
  updatedAt: x.updatedAt,
});

function fleet(n: number) {
  const ctxs = Array.from({ length: n }, (_, i) =>
    createContext(
      { id: `m${i}`, name: `M${i}`, kind: 'xtool', simulated: true },
      { visibility: alwaysVisible },
    ),
  );
  let renders = 0;
  for (const ctx of ctxs) {
    let prev = select(ctx.snapshot.getState());
    ctx.snapshot.subscribe((s) => {
      const next = select(s);
      if (!shallow(prev, next)) {
        renders++;
        prev = next;
      }
    });
  }
  return { ctxs, renders: () => renders };
}

const heap0 = heapMiB();
const results: Record<number, number> = {};
// Keep every fleet alive until the heap is measured.
const keep: Array<ReturnType<typeof fleet>> = [];
for (const n of [10, 100, 500]) {
  const f = fleet(n);
  keep.push(f);
  let t = 0;
  const target = f.ctxs[0];
  if (!target) throw new Error('no machines');
  // One machine reports progress: only its own tile should notice.
  const one = measure(2000, () => {
    t++;
    target.snapshot.setState({
      job: { name: 'part.nc', progress: (t % 100) / 100, elapsed: t, remaining: 100 - t },
      updatedAt: t,
    });
  });
  const before = f.renders();
  target.snapshot.setState({ updatedAt: -1 });
  const after = f.renders();
  // Every machine reports at once (a full poll round).
  const all = measure(50, () => {
    t++;
    for (const c of f.ctxs) c.snapshot.setState({ updatedAt: t, activity: t % 2 ? 'running' : 'idle' });
  });
  results[n] = one.median_ms;
  report({ name: `one machine update, fleet of ${n}`, ...one, tile_renders_for_one_update: after - before });
  report({
    name: `full poll round, fleet of ${n}`,
    ...all,
    per_machine_us: round((all.median_ms / n) * 1000, 2),
  });
}
report({
  name: 'scaling: one-machine update cost 500 vs 10 machines (ratio, ~1 means independent)',
  ratio: round((results[500] ?? 0) / (results[10] || 1), 2),
});
report({
  name: `heap of ${keep.reduce((a, f) => a + f.ctxs.length, 0)} machines (stores, logs, command runners)`,
  heap_mib: heapMiB(),
  heap_before_mib: heap0,
});
