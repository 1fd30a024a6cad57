import { useEffect, useMemo } from 'react';
import { useStore } from 'zustand';
import { allRuntimes, fleetStore } from '../fleet/fleet';
import { useCan, useDerived } from '../fleet/react';
import type { Alarm } from '../fleet/types';
import { Button, Dialog, formatTime } from '../ui';

export interface Blocking {
  machineId: string;
  machineName: string;
  alarm: Alarm;
}

function collect(): Blocking[] {
  const out: Blocking[] = [];
  for (const rt of allRuntimes()) {
    for (const a of rt.snapshot.getState().alarms) {
      if (a.blocking && !a.acknowledged)
        out.push({ machineId: rt.info.id, machineName: rt.info.name, alarm: a });
    }
  }
  return out;
}

/** A repeating alarm tone while a blocking alarm is unacknowledged (WebAudio; silent where not allowed). */
function useAlarmSound(active: boolean): void {
  useEffect(() => {
    if (!active) return;
    const Ctx = window.AudioContext;
    if (!Ctx) return;
    let ctx: AudioContext | null = null;
    try {
      ctx = new Ctx();
    } catch {
      return;
    }
    const beep = () => {
      if (!ctx) return;
      const o = ctx.createOscillator();
      const g = ctx.createGain();
      o.frequency.value = 880;
      g.gain.value = 0.15;
      o.connect(g).connect(ctx.destination);
      o.start();
      o.stop(ctx.currentTime + 0.35);
    };
    beep();
    const t = setInterval(beep, 1200);
    return () => {
      clearInterval(t);
      void ctx?.close();
    };
  }, [active]);
}

/** The unacknowledged blocking alarms of every machine (the App makes the page inert while any). */
export function useBlockingAlarms(): Blocking[] {
  const machines = useStore(fleetStore, (s) => s.machines);
  // Every runtime's snapshot (the list changes with the fleet).
  // eslint-disable-next-line react-hooks/exhaustive-deps
  const sources = useMemo(() => allRuntimes().map((rt) => rt.snapshot), [machines]);
  const blocking = useDerived(
    sources,
    collect,
    (a, b) => a.length === b.length && a.every((p, i) => p.alarm === b[i]?.alarm),
  );
  return blocking;
}

/**
 * Critical alarms that block every page until acknowledged (xTool flame detection): a modal
 * alert dialog above everything, also above a dialog that was open. The page behind is inert
 * (App.tsx); Escape does not dismiss it, only the acknowledgement does.
 */
export function AlarmBanner({ blocking }: { blocking: Blocking[] }) {
  const canAck = useCan('operator');
  useAlarmSound(blocking.length > 0);
  if (blocking.length === 0) return null;
  return (
    <Dialog
      title="Critical alarm"
      role="alertdialog"
      dismissible={false}
      // Read the alarm first: no acknowledgement by an Enter meant for something else.
      initialFocus="dialog"
      className="alarm-dialog"
      testId="blocking-alarm"
    >
      <div className="alarm-box">
        {blocking.map((b) => (
          <div key={`${b.machineId}:${b.alarm.id}`} className="alarm-item">
            <div className="alarm-title">
              <span aria-hidden="true">⚠</span> {b.machineName}
            </div>
            <div className="alarm-message">{b.alarm.message}</div>
            <div className="small">since {formatTime(b.alarm.since)}</div>
            {canAck ? (
              <Button
                variant="danger"
                data-testid={`ack-${b.machineId}`}
                onClick={() =>
                  allRuntimes()
                    .find((r) => r.info.id === b.machineId)
                    ?.session?.acknowledgeAlarm?.(b.alarm.id)
                }
              >
                I have checked the machine — acknowledge
              </Button>
            ) : (
              <p>An operator must acknowledge this alarm at the machine.</p>
            )}
          </div>
        ))}
      </div>
    </Dialog>
  );
}
