import { useStoreSelect } from '../../../fleet/react';
import { formatNumber } from '../../../ui';
import type { G2coreSession } from '../session';

/** On the fleet tile: the work position of every enabled axis, one line (the tile already shows the state). */
export function G2coreTile({ session }: { session: G2coreSession }) {
  const line = useStoreSelect(session.detail, (d) =>
    typeof d.sr.stat !== 'number'
      ? null
      : d.axes
          .map((a) => {
            const v = d.sr[`pos${a}`];
            return `${a.toUpperCase()} ${typeof v === 'number' ? formatNumber(v, 2) : '—'}`;
          })
          .join('  '),
  );
  if (line === null) return null;
  return (
    <div className="mono" style={{ fontSize: '0.9rem' }} data-testid="g2-tile">
      {line}
    </div>
  );
}
