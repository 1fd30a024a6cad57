import { useEffect, useMemo, useState, useSyncExternalStore } from 'react';
import { useStore } from 'zustand';
import { allRuntimes, fleetStore } from '../fleet/fleet';
import { useCan, useDerived } from '../fleet/react';
import { Button, Dialog, formatTime } from '../ui';
import { Link } from './router';
import { acknowledgeAlarm, alarmFeed, onNewAlarm, type AckTarget, type AlarmRecord } from './alarms/feed';

/**
 * Critical alarms on every page until a person acknowledges them, from the gateway's alarm centre
 * (which sees them whether or not a page is open) and from this page's own view of a machine
 * (which may see a flame a poll before the list does). A blocking alarm (an xTool flame) is a
 * modal alert above everything (the page behind is inert, App.tsx); the others a banner at the
 * top of every page, so the machine page that clears them stays usable. A tone repeats while any
 * is unacknowledged, unless this tablet muted it.
 */

export interface Blocking {
  machineId: string;
  machineName: string;
  /** The condition (the family's alarm id); one per machine. */
  key: string;
  message: string;
  since: number;
  blocking: boolean;
  /** The alarm centre's record; null while only this page has seen it. */
  recordId: string | null;
}

interface LocalAlarm {
  machineId: string;
  machineName: string;
  key: string;
  message: string;
  since: number;
}

function collectLocal(): LocalAlarm[] {
  const out: LocalAlarm[] = [];
  for (const rt of allRuntimes()) {
    for (const a of rt.snapshot.getState().alarms) {
      if (a.blocking && !a.acknowledged)
        out.push({
          machineId: rt.info.id,
          machineName: rt.info.name,
          key: a.id,
          message: a.message,
          since: a.since,
        });
    }
  }
  return out;
}

/** Every unacknowledged critical alarm: the alarm centre's, and this page's own not yet in it. */
export function criticalAlarms(
  records: readonly AlarmRecord[] | null,
  local: readonly LocalAlarm[],
): Blocking[] {
  const out: Blocking[] = [];
  for (const r of records ?? []) {
    if (r.severity !== 'critical' || r.ackAt !== null) continue;
    out.push({
      machineId: r.machine,
      machineName: r.machineName,
      key: r.key,
      message: r.text,
      since: r.since,
      blocking: r.blocking,
      recordId: r.id,
    });
  }
  // The list has it unacknowledged: shown from the list. An acknowledged record of the same key may
  // be an earlier alarm (the list can miss a flame while the laser's socket reconnects): this
  // page's own alarm stays until it is acknowledged here, or seen acknowledged elsewhere (feed.ts).
  for (const l of local) {
    if (records?.some((r) => r.machine === l.machineId && r.key === l.key && r.ackAt === null)) continue;
    out.push({ ...l, blocking: true, recordId: null });
  }
  return out;
}

/** The unacknowledged critical alarms of every machine this person may see. */
export function useCriticalAlarms(): Blocking[] {
  const machines = useStore(fleetStore, (s) => s.machines);
  const records = useStore(alarmFeed, (s) => s.records);
  // Every runtime's snapshot (the list changes with the fleet).
  // eslint-disable-next-line react-hooks/exhaustive-deps
  const sources = useMemo(() => allRuntimes().map((rt) => rt.snapshot), [machines]);
  const local = useDerived(
    sources,
    collectLocal,
    (a, b) =>
      a.length === b.length && a.every((p, i) => p.key === b[i]?.key && p.machineId === b[i]?.machineId),
  );
  return useMemo(() => criticalAlarms(records, local), [records, local]);
}

/** The blocking ones (an xTool flame): App makes the page inert while any. */
export function useBlockingAlarms(): Blocking[] {
  const all = useCriticalAlarms();
  return useMemo(() => all.filter((b) => b.blocking), [all]);
}

// ---------------------------------------------------------------- sound, per tablet

const SOUND_KEY = 'shopdeck.alarmSound';
const soundListeners = new Set<() => void>();

export function alarmSoundOn(): boolean {
  try {
    return localStorage.getItem(SOUND_KEY) !== 'off';
  } catch {
    return true;
  }
}

export function setAlarmSound(on: boolean): void {
  try {
    localStorage.setItem(SOUND_KEY, on ? 'on' : 'off');
  } catch {
    // storage refused: the choice lasts for this page only
  }
  for (const l of soundListeners) l();
}

export function useAlarmSoundSetting(): boolean {
  return useSyncExternalStore(
    (fn) => {
      soundListeners.add(fn);
      return () => soundListeners.delete(fn);
    },
    alarmSoundOn,
    () => true,
  );
}

/** A repeating tone while `active` (Web Audio; silent where the browser allows no sound yet). */
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

// ---------------------------------------------------------------- notifications

/** A system notification for each new critical or warning alarm, where this person allowed them. */
function useAlarmNotifications(): void {
  useEffect(
    () =>
      onNewAlarm((r) => {
        if (r.severity === 'info' || r.ackAt !== null) return;
        if (typeof Notification === 'undefined' || Notification.permission !== 'granted') return;
        try {
          new Notification(`${r.severity === 'critical' ? 'Critical alarm' : 'Alarm'}: ${r.machineName}`, {
            body: r.text,
            tag: `shopdeck-alarm-${r.id}`,
            requireInteraction: r.severity === 'critical',
          });
        } catch {
          // Some browsers only allow notifications from a service worker: the banner still shows.
        }
      }),
    [],
  );
}

// ---------------------------------------------------------------- the views

function targetOf(b: Blocking): AckTarget {
  return b.recordId ? { id: b.recordId } : { machine: b.machineId, key: b.key };
}

function AckButton({ b, onError }: { b: Blocking; onError: (e: string | null) => void }) {
  const [busy, setBusy] = useState(false);
  return (
    <Button
      variant="danger"
      data-testid={`ack-${b.machineId}`}
      busy={busy}
      disabled={busy}
      onClick={() => {
        setBusy(true);
        void acknowledgeAlarm(targetOf(b)).then((e) => {
          setBusy(false);
          onError(e);
        });
      }}
    >
      I have checked the machine — acknowledge
    </Button>
  );
}

function SoundToggle() {
  const on = useAlarmSoundSetting();
  return (
    <Button
      small
      onClick={() => setAlarmSound(!on)}
      data-testid="alarm-sound-toggle"
      aria-pressed={!on}
      aria-label={
        on ? 'Mute the alarm sound on this tablet' : 'Alarm sound is muted on this tablet — turn on'
      }
    >
      {on ? 'Mute' : 'Muted — turn on'}
    </Button>
  );
}

/**
 * The modal alert for blocking alarms (xTool flame): above everything, also above a dialog that
 * was open; Escape does not dismiss it, only the acknowledgement does.
 */
export function AlarmBanner({ blocking }: { blocking: Blocking[] }) {
  const canAck = useCan('operator');
  const critical = useCriticalAlarms();
  const soundOn = useAlarmSoundSetting();
  const [error, setError] = useState<string | null>(null);
  useAlarmSound(critical.length > 0 && soundOn);
  useAlarmNotifications();
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
          <div key={`${b.machineId}:${b.key}`} className="alarm-item">
            <div className="alarm-title">
              <span aria-hidden="true">⚠</span> {b.machineName}
            </div>
            <div className="alarm-message">{b.message}</div>
            <div className="small">since {formatTime(b.since)}</div>
            {canAck ? (
              <AckButton b={b} onError={setError} />
            ) : (
              <p>An operator must acknowledge this alarm at the machine.</p>
            )}
          </div>
        ))}
        {error && (
          <p role="alert" className="alarm-error">
            {error}
          </p>
        )}
        <SoundToggle />
      </div>
    </Dialog>
  );
}

/** Which critical alarms the banner shows in full (this page's machine) and which as one line. */
export function splitForBanner(
  critical: readonly Blocking[],
  here: string | null,
  kiosk: boolean,
): { full: Blocking[]; others: Blocking[] } {
  return {
    // This page's machine: in full, with acknowledge (a blocking one is the modal's).
    full: critical.filter((b) => b.machineId === here && !b.blocking),
    // The others: one line. On a kiosk every other machine's, blocking too (the modal is for the
    // kiosk's own machine: an operator at the laser acknowledges nothing he cannot see).
    others: critical.filter((b) => b.machineId !== here && (kiosk || !b.blocking)),
  };
}

/** The one line of the other machines' critical alarms ("3 critical — Router, Plasma, Printer 3"). */
export function othersLine(others: readonly Blocking[], kiosk: boolean): string {
  const n = others.length;
  if (kiosk) return `${n} other ${n === 1 ? 'alarm' : 'alarms'} in the shop`;
  if (n === 1) return `Critical — ${others[0]!.machineName}: ${others[0]!.message}`;
  const names = [...new Set(others.map((b) => b.machineName))];
  return `${n} critical — ${names.join(', ')}`;
}

/**
 * The critical alarms that do not block, at the top of every page: the machine of this page
 * (`hideOn`) in full with its acknowledgement, every other as one compact line that leads to the
 * alarm centre (where they are acknowledged, as on each machine's page). `kiosk`: no way out of
 * the page and nothing to acknowledge of another machine, only their number.
 */
export function CriticalBanner({ hideOn, kiosk = false }: { hideOn?: string | null; kiosk?: boolean }) {
  const canAck = useCan('operator');
  const critical = useCriticalAlarms();
  const [error, setError] = useState<string | null>(null);
  const { full, others } = splitForBanner(critical, hideOn ?? null, kiosk);
  if (full.length === 0 && others.length === 0) return null;
  return (
    <div className="critical-banner" role="alert" data-testid="critical-banner">
      {full.map((b) => (
        <div
          key={`${b.machineId}:${b.key}`}
          className="critical-item"
          data-testid={`critical-${b.machineId}`}
        >
          <span className="critical-what">
            <span aria-hidden="true">⚠</span> <strong>{b.machineName}</strong>: {b.message}{' '}
            <span className="small">since {formatTime(b.since)}</span>
          </span>
          {canAck ? (
            <AckButton b={b} onError={setError} />
          ) : (
            <span className="small">An operator must acknowledge it.</span>
          )}
        </div>
      ))}
      {error && <p className="alarm-error">{error}</p>}
      {(others.length > 0 || full.length > 0) && (
        <div className="critical-line" data-testid="critical-others">
          {others.length > 0 && (
            <span
              className="critical-summary"
              data-testid="critical-summary"
              title={othersLine(others, kiosk)}
            >
              <span aria-hidden="true">⚠</span> {othersLine(others, kiosk)}
            </span>
          )}
          {others.length > 0 && !kiosk && (
            <Link to="/alarms" className="critical-view">
              View
            </Link>
          )}
          <SoundToggle />
        </div>
      )}
    </div>
  );
}
