import type { TabProps } from '../../../fleet/contract';
import { useSnapshot, useStoreSelect } from '../../../fleet/react';
import { Button, KeyValues, Notice, Panel, ProgressBar, formatNumber } from '../../../ui';
import { DEFAULT_HEIGHT_MAP } from '../reads';
import type { DuetSession } from '../session';
import type { HeightMap as Map } from '../wire';
import { DuetFrame } from './common';
import { useHeightMap } from './reads';

/** Blue (low) → green (0) → red (high), symmetric around zero. */
export function heightColor(v: number, range: number): string {
  const t = Math.max(-1, Math.min(1, range > 0 ? v / range : 0));
  const hue = 120 - t * 120; // -1 → 240 (blue), 0 → 120 (green), 1 → 0 (red)
  return `hsl(${hue.toFixed(0)} 70% 50%)`;
}

export function heightStats(m: Map): { min: number; max: number; mean: number; rms: number; points: number } {
  const all = m.points.flat();
  const n = all.length || 1;
  const mean = all.reduce((a, b) => a + b, 0) / n;
  const rms = Math.sqrt(all.reduce((a, b) => a + (b - mean) ** 2, 0) / n);
  return { min: Math.min(...all), max: Math.max(...all), mean, rms, points: all.length };
}

/** The mesh file `move.compensation.file` points at, as a 2-D colour map (y up, as on the bed). */
export function HeightMap({ session }: TabProps<DuetSession>) {
  const file = useStoreSelect(session.store, (s) => s.model?.move.compensation?.file ?? null);
  const link = useSnapshot(session.ctx, (s) => s.link);
  // A query keyed by the file: another compensation file is another map.
  const hm = useHeightMap(session, file ?? DEFAULT_HEIGHT_MAP, link === 'online');
  const m = hm.map;
  const stats = m ? heightStats(m) : null;
  const range = stats ? Math.max(Math.abs(stats.min), Math.abs(stats.max), 0.01) : 1;
  const cell = 48;
  return (
    <DuetFrame session={session}>
      <Panel
        title="Height map"
        testId="duet-heightmap"
        actions={<Button onClick={hm.refetch}>Reload</Button>}
      >
        <p className="ui-muted mono">{hm.path}</p>
        {hm.loading && <ProgressBar value={null} label="Loading height map" />}
        {hm.error && (
          <Notice tone="warn" title="No height map">
            {hm.error}
          </Notice>
        )}
        {m && stats && (
          <div className="ui-row" style={{ alignItems: 'flex-start' }}>
            <svg
              viewBox={`0 0 ${m.xnum * cell + 50} ${m.ynum * cell + 30}`}
              style={{ width: '100%', maxWidth: 560, height: 'auto' }}
              role="img"
              aria-label={`Height map ${m.xnum} by ${m.ynum} points, from ${formatNumber(stats.min, 3)} to ${formatNumber(stats.max, 3)} mm`}
              data-testid="duet-heightmap-svg"
            >
              {m.points.map((row, y) =>
                row.map((v, x) => {
                  const px = 40 + x * cell;
                  const py = (m.ynum - 1 - y) * cell;
                  return (
                    <g key={`${x}-${y}`}>
                      <rect
                        x={px}
                        y={py}
                        width={cell - 2}
                        height={cell - 2}
                        fill={heightColor(v, range)}
                        rx={4}
                      >
                        <title>{`X ${formatNumber(m.xmin + x * m.xspacing, 1)} Y ${formatNumber(m.ymin + y * m.yspacing, 1)}: ${formatNumber(v, 3, 'mm')}`}</title>
                      </rect>
                      <text
                        x={px + cell / 2 - 1}
                        y={py + cell / 2 + 4}
                        textAnchor="middle"
                        fontSize={11}
                        fill="#000"
                      >
                        {formatNumber(v, 2)}
                      </text>
                    </g>
                  );
                }),
              )}
              {m.points[0]?.map((_, x) => (
                <text
                  key={`x${x}`}
                  x={40 + x * cell + cell / 2}
                  y={m.ynum * cell + 16}
                  textAnchor="middle"
                  fontSize={10}
                  fill="currentColor"
                >
                  {formatNumber(m.xmin + x * m.xspacing, 0)}
                </text>
              ))}
              {m.points.map((_, y) => (
                <text
                  key={`y${y}`}
                  x={34}
                  y={(m.ynum - 1 - y) * cell + cell / 2 + 4}
                  textAnchor="end"
                  fontSize={10}
                  fill="currentColor"
                >
                  {formatNumber(m.ymin + y * m.yspacing, 0)}
                </text>
              ))}
            </svg>
            <KeyValues
              items={[
                ['Points', `${m.xnum} × ${m.ynum}`],
                ['Lowest', formatNumber(stats.min, 3, 'mm')],
                ['Highest', formatNumber(stats.max, 3, 'mm')],
                ['Mean', formatNumber(stats.mean, 3, 'mm')],
                ['RMS deviation', formatNumber(stats.rms, 3, 'mm')],
                ['Colours', 'blue low · green 0 · red high'],
              ]}
            />
          </div>
        )}
      </Panel>
    </DuetFrame>
  );
}
