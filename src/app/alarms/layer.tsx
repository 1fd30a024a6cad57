import { useEffect, useMemo } from 'react';
import { useStore } from 'zustand';
import { AlarmBanner, CriticalBanner, useBlockingAlarms } from '../AlarmBanner';
import { alarmFeed, startAlarmFeed } from './feed';
import { alarmSummary } from './summary';

/**
 * The alarm layer of every page (a chunk of its own, loaded when the first screen has shown):
 * follows the alarm centre's list, shows blocking alarms as a modal alert (on a kiosk, those of
 * its own machine), and tells the shell
 * what it needs (summary.ts).
 */
export function AlarmModal({ kioskMachine = null }: { kioskMachine?: string | null }) {
  useEffect(() => startAlarmFeed(), []);
  const all = useBlockingAlarms();
  // A kiosk blocks for its own machine only (the others are a line of the banner, CriticalBanner).
  const blocking = useMemo(
    () => (kioskMachine === null ? all : all.filter((b) => b.machineId === kioskMachine)),
    [all, kioskMachine],
  );
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
