import { memo } from 'react';
import { formatNumber } from './format';

export interface Series {
  name: string;
  /** [time ms, value] */
  points: ReadonlyArray<readonly [number, number]>;
  color?: string;
}

const PALETTE = ['#e5534b', '#4493f8', '#3fb950', '#d29922', '#a371f7', '#39c5cf', '#db61a2', '#768390'];

/** A small dependency-free SVG line chart over a time window. */
export const TimeSeriesChart = memo(function TimeSeriesChart(props: {
  series: readonly Series[];
  /** window (ms) ending at `now` */
  windowMs: number;
  now: number;
  height?: number;
  unit?: string;
  testId?: string;
  /** Said under the chart (where its earlier readings came from, or why there are none). */
  note?: string | null;
}) {
  const width = 600;
  const height = props.height ?? 180;
  const padL = 40;
  const padB = 18;
  const t0 = props.now - props.windowMs;
  let min = Infinity;
  let max = -Infinity;
  for (const s of props.series)
    for (const [t, v] of s.points)
      if (t >= t0 && Number.isFinite(v)) {
        if (v < min) min = v;
        if (v > max) max = v;
      }
  if (!Number.isFinite(min)) {
    min = 0;
    max = 1;
  }
  if (max - min < 1e-9) {
    max += 1;
    min -= 1;
  }
  const x = (t: number) => padL + ((t - t0) / props.windowMs) * (width - padL - 4);
  const y = (v: number) => 4 + (1 - (v - min) / (max - min)) * (height - padB - 8);
  const ticks = [min, (min + max) / 2, max];
  // What the chart holds, said (and readable by tests): the most readings of one series in the window.
  // The newest reading's time, too: once the window is full the count stays, the newest moves on.
  let readings = 0;
  let newest = 0;
  for (const s of props.series) {
    let n = 0;
    for (const [t] of s.points)
      if (t >= t0) {
        n++;
        if (t > newest) newest = t;
      }
    readings = Math.max(readings, n);
  }
  const span =
    props.windowMs % 60_000 === 0
      ? `${props.windowMs / 60_000} min`
      : `${Math.round(props.windowMs / 1000)} s`;
  const summary = `Last ${span}: ${readings} reading${readings === 1 ? '' : 's'}${
    props.series.length > 1 ? ` of ${props.series.length} sensors` : ''
  }`;
  return (
    <div data-testid={props.testId} data-readings={readings} data-newest={newest}>
      <svg
        className="ui-chart"
        viewBox={`0 0 ${width} ${height}`}
        preserveAspectRatio="none"
        role="img"
        aria-label={summary}
      >
        {ticks.map((v, i) => (
          <g key={i}>
            <line className="axis" x1={padL} x2={width} y1={y(v)} y2={y(v)} strokeDasharray="3 4" />
            <text x={2} y={y(v) + 4}>
              {formatNumber(v, Math.abs(max - min) < 10 ? 1 : 0)}
            </text>
          </g>
        ))}
        {props.series.map((s, i) => {
          const pts = s.points.filter(([t]) => t >= t0);
          if (pts.length === 0) return null;
          const d = pts
            .map(([t, v], j) => `${j === 0 ? 'M' : 'L'}${x(t).toFixed(1)},${y(v).toFixed(1)}`)
            .join('');
          return (
            <path
              key={s.name}
              d={d}
              fill="none"
              stroke={s.color ?? PALETTE[i % PALETTE.length]}
              strokeWidth={2}
              vectorEffect="non-scaling-stroke"
            />
          );
        })}
        <text x={padL} y={height - 3}>
          −{Math.round(props.windowMs / 1000)} s
        </text>
        <text x={width - 30} y={height - 3}>
          now
        </text>
      </svg>
      <div className="ui-legend">
        {props.series.map((s, i) => (
          <span key={s.name}>
            <i style={{ background: s.color ?? PALETTE[i % PALETTE.length] }} />
            {s.name}
            {props.unit ? ` (${props.unit})` : ''}
          </span>
        ))}
      </div>
      {props.note ? <p className="ui-muted">{props.note}</p> : null}
    </div>
  );
});
