import { useMemo, useState } from 'react';
import { useStore } from 'zustand';
import { Button, type Series } from '../../../ui';
import { TimeSeriesChart } from '../../../ui/TimeSeriesChart';
import type { PruntSession } from '../session';
import {
  earlierNote,
  useEarlierTemperatures,
  withEarlier,
  type Point,
} from '../../../fleet/server-temperatures';

const WINDOWS = [
  [60, '1 min'],
  [300, '5 min'],
  [600, '10 min'],
] as const;

type Kind = 'temperature' | 'position' | 'power';

function kindOf(name: string): Kind | null {
  if (/power/i.test(name)) return 'power';
  if (/position/i.test(name)) return 'position';
  if (/temperat/i.test(name)) return 'temperature';
  return null;
}

/** Temperatures, positions and heater powers over a time window; pause freezes the picture. */
export function LiveChart(props: { session: PruntSession }) {
  const h = props.session.history;
  const version = useStore(h.store, (s) => s.version);
  const names = useStore(h.store, (s) => s.names);
  const [windowS, setWindowS] = useState(300);
  const [kind, setKind] = useState<Kind>('temperature');
  const [frozen, setFrozen] = useState<number | null>(null);
  const shownVersion = frozen ?? version;
  // The last minutes the console's server kept (temperatures only), then the live points.
  const ctx = props.session.ctx;
  const earlier = useEarlierTemperatures(ctx.machine.id, ctx.now);
  const series = useMemo(() => {
    const out: Series[] = [];
    const kept = kind === 'temperature' && earlier.state === 'ok' ? earlier.byKey : null;
    const t = h.t;
    const end = t[t.length - 1] ?? 0;
    const from = end - windowS;
    let start = t.findIndex((x) => x >= from);
    if (start < 0) start = 0;
    // At most ~600 points per series: the chart stays cheap at 10 updates per second.
    const step = Math.max(1, Math.floor((t.length - start) / 600));
    for (const n of names) {
      if (kindOf(n) !== kind) continue;
      const col = h.cols.get(n);
      if (!col) continue;
      const points: Point[] = [];
      for (let i = start; i < t.length; i += step) {
        const v = col[i];
        if (v !== null && v !== undefined) points.push([(t[i] as number) * 1000, v]);
      }
      out.push({ name: n.split(' · ').pop() ?? n, points: withEarlier(kept?.get(n)?.points, points) });
    }
    // Sensors the server kept that no live tick has named yet (the page just opened).
    if (kept)
      for (const [key, e] of kept)
        if (!names.includes(key) && kindOf(key) === 'temperature')
          out.push({ name: e.name, points: e.points });
    return out;
    // eslint-disable-next-line react-hooks/exhaustive-deps
  }, [shownVersion, names, windowS, kind, earlier]);
  const now = h.t.length ? (h.t[h.t.length - 1] as number) * 1000 : ctx.now();
  return (
    <div data-testid="prunt-chart">
      <div className="ui-row" style={{ marginBottom: 8 }}>
        <select
          className="ui-input"
          value={kind}
          onChange={(e) => setKind(e.target.value as Kind)}
          aria-label="Chart values"
        >
          <option value="temperature">Temperatures (°C)</option>
          <option value="position">Positions (mm)</option>
          <option value="power">Heater powers (0–1)</option>
        </select>
        <select
          className="ui-input"
          value={windowS}
          onChange={(e) => setWindowS(Number(e.target.value))}
          aria-label="Time window"
        >
          {WINDOWS.map(([s, l]) => (
            <option key={s} value={s}>
              {l}
            </option>
          ))}
        </select>
        <Button onClick={() => setFrozen(frozen === null ? version : null)}>
          {frozen === null ? 'Pause chart' : 'Resume chart'}
        </Button>
      </div>
      {series.length === 0 ? (
        <p className="ui-muted">
          {kind === 'temperature' ? (earlierNote(earlier) ?? 'No data yet.') : 'No data yet.'}
        </p>
      ) : (
        <TimeSeriesChart
          series={series}
          windowMs={windowS * 1000}
          now={now}
          unit={kind === 'temperature' ? '°C' : kind === 'position' ? 'mm' : ''}
          testId="prunt-live-chart"
          note={kind === 'temperature' ? earlierNote(earlier) : null}
        />
      )}
    </div>
  );
}
