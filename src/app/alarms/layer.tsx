import { useEffect } from 'react';
import { useStore } from 'zustand';
import { AlarmBanner, CriticalBanner, useBlockingAlarms } from '../AlarmBanner';
import { alarmFeed, startAlarmFeed } from './feed';
import { alarmSummary } from './summary';

/**
 * The alarm layer of every page (a chunk of its own, loaded when the first screen has shown):
 * follows the alarm centre's list, shows blocking alarms as a modal alert, and tells the shell
 * what it needs (summary.ts).
 */
export function AlarmModal() {
  useEffect(() => startAlarmFeed(), []);
  const blocking = useBlockingAlarms();
  const unacknowledged = useStore(
    alarmFeed,
    (s) => s.records?.filter((r) => r.clearedAt === null && r.ackAt === null).length ?? 0,
  );
  useEffect(() => {
    alarmSummary.setState({ blocking: blocking.length, unacknowledged });
  }, [blocking.length, unacknowledged]);
  return <AlarmBanner blocking={blocking} />;
}

/** The banner of critical alarms that do not block, at the top of every page. */
export function AlarmStrip({ hideOn, kiosk }: { hideOn: string | null; kiosk: boolean }) {
  // When the list cannot be read the page says so: never an all-clear it does not know.
  const error = useStore(alarmFeed, (s) => s.error);
  return (
    <>
      {error && (
        <p className="alarm-error" role="status" data-testid="alarms-unreadable">
          Cannot read the alarms: {error}
        </p>
      )}
      <CriticalBanner hideOn={hideOn} kiosk={kiosk} />
    </>
  );
}
