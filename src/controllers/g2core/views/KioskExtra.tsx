import type { TabProps } from '../../../fleet/contract';
import type { G2coreSession } from '../session';
import { Overrides } from './Overrides';

/** The kiosk's view of a g2core machine, under its job controls: the feed and spindle overrides. */
export function KioskExtra(props: TabProps<G2coreSession>) {
  return <Overrides {...props} />;
}
