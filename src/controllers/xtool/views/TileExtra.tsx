import type { TabProps } from '../../../fleet/contract';
import { useStoreSelect } from '../../../fleet/react';
import type { XtoolSession } from '../session';

/** On the fleet tile: what the fleet activity cannot say (waiting for the button, no SD card). */
export function TileExtra({ session }: TabProps<XtoolSession>) {
  const d = useStoreSelect(session.detail, (s) => ({
    state: s.machine.state,
    sd: s.periphery?.sdCard,
    unsupported: s.model.family === 'unsupported',
  }));
  const lines: string[] = [];
  if (d.state === 'job-loaded' || d.state === 'frame-ready')
    lines.push('Waiting for the button on the machine');
  if (d.sd === false) lines.push('No SD card');
  if (d.unsupported) lines.push('Unsupported xTool model');
  if (!lines.length) return null;
  return (
    <div className="ui-muted" data-testid="xtool-tile-extra">
      {lines.join(' · ')}
    </div>
  );
}
