import { fleetStore } from '../../fleet/fleet';
import { arrangeFleet, flatOrder } from '../fleet-views/arrange';
import { familyLabel, liveState } from '../fleet-views/live';
import { fleetPrefsStore } from '../fleet-views/prefs';

/**
 * The machine after (`step` 1) or before (-1) `current` in the fleet page's current order,
 * wrapping round. A machine the view's filters hide steps through the whole fleet in the view's
 * sort order instead. Null when there is no other machine.
 */
export function neighbourMachine(current: string, step: 1 | -1): string | null {
  const machines = fleetStore.getState().machines;
  const prefs = fleetPrefsStore.getState();
  let order = flatOrder(arrangeFleet(machines, prefs, liveState, familyLabel));
  if (!order.includes(current))
    order = flatOrder(
      arrangeFleet(machines, { ...prefs, state: 'all', family: 'all', q: '' }, liveState, familyLabel),
    );
  const to = stepMachine(order, current, step);
  return to === current ? null : to;
}

/**
 * The machine `step` places after `current` in `order` (wrapping round), or null when the order is
 * empty. A machine not in the order (filtered out) starts from the first or the last.
 */
export function stepMachine(order: readonly string[], current: string, step: 1 | -1): string | null {
  if (order.length === 0) return null;
  const i = order.indexOf(current);
  if (i < 0) return (step === 1 ? order[0] : order[order.length - 1]) ?? null;
  return order[(i + step + order.length) % order.length] ?? null;
}
