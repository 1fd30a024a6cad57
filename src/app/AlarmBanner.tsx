import { useEffect, useState } from 'react';
import { useStore } from 'zustand';
import { allRuntimes, fleetStore } from '../fleet/fleet';
import { useCan } from '../fleet/react';
import type { Alarm } from '../fleet/types';
import { Button, formatTime } from '../ui';

interface Blocking {
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

/** Critical alarms that block every page until acknowledged (xTool flame detection). */
export function AlarmBanner() {
  const machines = useStore(fleetStore, (s) => s.machines);
  const [blocking, setBlocking] = useState<Blocking[]>([]);
  const canAck = useCan('operator');
  useEffect(() => {
    const update = () => {
      const next = collect();
      setBlocking((prev) =>
        prev.length === next.length && prev.every((p, i) => p.alarm === next[i]?.alarm) ? prev : next,
      );
    };
    update();
    const unsubs = allRuntimes().map((rt) => rt.snapshot.subscribe(update));
    return () => unsubs.forEach((u) => u());
  }, [machines]);
  useAlarmSound(blocking.length > 0);
  if (blocking.length === 0) return null;
  return (
    <div
      className="alarm-overlay"
      role="alertdialog"
      aria-modal="true"
      aria-label="Critical alarm"
      data-testid="blocking-alarm"
    >
      <div className="alarm-box">
        {blocking.map((b) => (
          <div key={`${b.machineId}:${b.alarm.id}`} className="alarm-item">
            <div className="alarm-title">⚠ {b.machineName}</div>
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
    </div>
  );
}
