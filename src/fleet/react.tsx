import { useCallback, useId, useMemo, useState, useSyncExternalStore, type ReactNode } from 'react';
import { useStore, type StoreApi } from 'zustand';
import { useShallow } from 'zustand/react/shallow';
import { Button, Dialog, ScrollRegion, downloadText, formatTime } from '../ui';
import { authStore } from './auth';
import { CommandNotConfirmed, confirmationText, type CommandDecl, type CommandRunner } from './commands';
import type { SessionContext } from './contract';
import { useBlockedReason } from './kernel/commands';
import type { Scheduler } from './kernel/scheduler';
import { useScheduler } from './kernel/use-scheduler';
export { SchedulerContext, useScheduler } from './kernel/use-scheduler';
import type { LogEntry, MachineLog } from './log';
import type { MachineSnapshot, Role } from './types';
import { roleAtLeast } from './types';

/**
 * React glue: components read stores through selectors that return stable references
 * (useShallow for objects), so a tile re-renders only when its own machine's values change.
 */
export function useStoreSelect<T, U>(store: StoreApi<T>, selector: (s: T) => U): U {
  return useStore(store, useShallow(selector));
}

export function useSnapshot<U>(
  ctx: Pick<SessionContext, 'snapshot'>,
  selector: (s: MachineSnapshot) => U,
): U {
  return useStore(ctx.snapshot, useShallow(selector));
}

/**
 * One shared clock per period (issue 16): every component that shows a time (data ages,
 * countdowns) reads the same ticker, the scheduler's tick of that period, instead of a timer
 * each; only those components re-render on a tick. The ticker stops when nobody reads it.
 */
interface Clock {
  now: number;
  listeners: Set<() => void>;
  stop: (() => void) | null;
}
const clocks = new WeakMap<Scheduler, Map<number, Clock>>();

function clockOf(scheduler: Scheduler, everyMs: number): Clock {
  let byPeriod = clocks.get(scheduler);
  if (!byPeriod) {
    byPeriod = new Map();
    clocks.set(scheduler, byPeriod);
  }
  let c = byPeriod.get(everyMs);
  if (!c) {
    c = { now: scheduler.now(), listeners: new Set(), stop: null };
    byPeriod.set(everyMs, c);
  }
  return c;
}

const pageHidden = (): boolean => typeof document !== 'undefined' && document.hidden;

function tick(scheduler: Scheduler, c: Clock): void {
  c.now = scheduler.now();
  for (const l of [...c.listeners]) l();
}

const watchingVisibility = new WeakSet<Scheduler>();
/** Shown again: every running clock reads the time at once. */
function watchVisibility(scheduler: Scheduler): void {
  if (watchingVisibility.has(scheduler) || typeof document === 'undefined') return;
  watchingVisibility.add(scheduler);
  document.addEventListener('visibilitychange', () => {
    if (pageHidden()) return;
    for (const c of clocks.get(scheduler)?.values() ?? []) if (c.stop !== null) tick(scheduler, c);
  });
}

function subscribeClock(scheduler: Scheduler, everyMs: number, listener: () => void): () => void {
  const c = clockOf(scheduler, everyMs);
  c.listeners.add(listener);
  if (c.stop === null) {
    c.now = scheduler.now();
    // The scheduler's one tick of this period: every reader updates in the same frame.
    // A hidden page shows nothing: it does not re-render for the clock (it catches up when shown).
    c.stop = scheduler.every(everyMs, () => {
      if (!pageHidden()) tick(scheduler, c);
    });
    watchVisibility(scheduler);
  }
  return () => {
    c.listeners.delete(listener);
    if (c.listeners.size === 0 && c.stop !== null) {
      c.stop();
      c.stop = null;
    }
  };
}

/** The time now, updated every `everyMs` by the shared clock of that period. */
export function useNow(everyMs = 1000): number {
  const scheduler = useScheduler();
  const subscribe = useCallback(
    (l: () => void) => subscribeClock(scheduler, everyMs, l),
    [scheduler, everyMs],
  );
  return useSyncExternalStore(subscribe, () => clockOf(scheduler, everyMs).now);
}

/** Something that tells when it changed (a zustand store). */
interface Notifier {
  subscribe(listener: () => void): () => void;
}

/**
 * A value derived from several stores (every machine's snapshot), as an external store for React:
 * recomputed when any of them changes, and React is told only when the value changed (`equal`).
 * Not a setState per store change: React queues even an update it bails out of until the
 * component renders again, so at every machine's data rate those piled up (issue 16: the heap of
 * a 100-machine fleet page grew by a megabyte a minute).
 */
export function derivedStore<T>(
  sources: readonly Notifier[],
  compute: () => T,
  equal: (a: T, b: T) => boolean,
): { subscribe(notify: () => void): () => void; getSnapshot(): T } {
  let value = compute();
  return {
    subscribe(notify) {
      const recompute = () => {
        const next = compute();
        if (equal(value, next)) return;
        value = next;
        notify();
      };
      const unsubs = sources.map((s) => s.subscribe(recompute));
      recompute();
      return () => unsubs.forEach((u) => u());
    },
    getSnapshot: () => value,
  };
}

/** `derivedStore` in a component; made again when `sources` changes (a new fleet). */
export function useDerived<T>(
  sources: readonly Notifier[],
  compute: () => T,
  equal: (a: T, b: T) => boolean,
): T {
  // compute and equal are read when the sources change (they depend on nothing else).
  // eslint-disable-next-line react-hooks/exhaustive-deps
  const store = useMemo(() => derivedStore(sources, compute, equal), [sources]);
  return useSyncExternalStore(store.subscribe, store.getSnapshot);
}

/** The role the UI acts as (open mode: supervisor). */
export function useRole(): Role {
  return useStore(authStore, (s) => (s.mode === 'secured' ? (s.user?.role ?? 'viewer') : 'supervisor'));
}

export function useCan(role: Role): boolean {
  return roleAtLeast(useRole(), role);
}

/**
 * The one way a command leaves the console: a button that confirms (by hazard), shows the
 * in-flight state, cannot be sent twice, and says why it is disabled.
 */
export function CommandButton<A>(props: {
  runner: CommandRunner;
  snapshot: StoreApi<MachineSnapshot>;
  command: CommandDecl<A>;
  args: A;
  children?: ReactNode;
  /** The accessible name when the children are not plain text (default: the command's label). */
  label?: string;
  variant?: 'primary' | 'secondary' | 'danger';
  small?: boolean;
  /** Hide instead of disabling when the user's role is too low. */
  hideWhenNotAllowed?: boolean;
  /** Extra confirmation body (what exactly will happen). */
  details?: ReactNode;
  /** The question to ask first instead of the command's own (an emergency stop on a touch screen). */
  confirmText?: string;
  /** The dismiss button of the question: what it keeps ("Keep printing"); default by hazard. */
  dismissLabel?: string;
  onDone?: (result: string) => void;
  onError?: (message: string) => void;
  testId?: string;
}) {
  const { runner, command, args } = props;
  const role = useRole();
  const inFlight = useStore(runner.state, (s) => Boolean(s.inFlight[command.id]));
  const last = useStore(runner.state, (s) => s.last[command.id]);
  const [confirmStep, setConfirmStep] = useState(0);
  const [error, setError] = useState<string | null>(null);
  /** The last error leaves it open whether the command reached the machine (not a failure). */
  const [unsure, setUnsure] = useState(false);
  const allowed = roleAtLeast(role, command.role);
  // Follows the runner, the snapshot and every store the command's availability reads.
  const reason = useBlockedReason(runner, props.snapshot, command);
  const confirmText = props.confirmText ?? confirmationText(command, args);
  const reasonId = useId();

  const send = useCallback(async () => {
    setConfirmStep(0);
    setError(null);
    setUnsure(false);
    try {
      const r = await runner.run(command, args);
      props.onDone?.(r);
    } catch (e) {
      const msg = e instanceof Error ? e.message : String(e);
      setUnsure(e instanceof CommandNotConfirmed);
      setError(msg);
      props.onError?.(msg);
    }
    // eslint-disable-next-line react-hooks/exhaustive-deps
  }, [runner, command, args]);

  if (!allowed && props.hideWhenNotAllowed) return null;
  const onClick = () => {
    if (reason) {
      // Tablets have no hover: a tap on an unavailable command says why, on screen.
      setUnsure(false);
      setError(`Not available: ${reason}`);
      return;
    }
    if (confirmText) setConfirmStep(1);
    else void send();
  };
  const title =
    reason ??
    (last && !last.ok
      ? `${last.notConfirmed ? 'Last attempt not confirmed' : 'Last attempt failed'}: ${last.message}`
      : command.label);
  // Stop controls are marked: nothing may focus one by itself (a stray Enter would send it).
  const stop = command.hazard === 'stop' || undefined;
  // Never "Cancel" for the dismiss: in a question about cancelling it would mean both answers.
  const dismiss = props.dismissLabel ?? (stop ? 'Keep running' : 'Go back');
  return (
    <span className={`ui-cmd${reason ? ' unavailable' : ''}`}>
      <Button
        variant={
          props.variant ??
          (command.hazard === 'stop' || command.hazard === 'dangerous' ? 'danger' : 'secondary')
        }
        small={props.small}
        busy={inFlight}
        disabled={inFlight}
        aria-disabled={Boolean(reason) || undefined}
        aria-describedby={reason && !error ? reasonId : undefined}
        onClick={onClick}
        title={title}
        aria-label={props.label ?? (typeof props.children === 'string' ? undefined : command.label)}
        data-testid={props.testId ?? `cmd-${command.id}`}
        data-hazard={command.hazard}
        data-stop={stop}
      >
        {inFlight ? `${command.label}…` : (props.children ?? command.label)}
      </Button>
      {/* Why it is unavailable, as text: shown under it on touch screens (no hover there). */}
      {reason && !error && (
        <span className="ui-cmd-reason small" id={reasonId} data-testid={`cmd-reason-${command.id}`}>
          {reason}
        </span>
      )}
      {error && (
        <span
          className="ui-muted"
          role="alert"
          style={{ color: unsure ? 'var(--warn)' : 'var(--bad)' }}
          data-testid={`cmd-error-${command.id}`}
          data-not-confirmed={unsure || undefined}
        >
          {error}
        </span>
      )}
      {confirmStep > 0 && confirmText && (
        <Dialog
          title={confirmStep === 2 ? `Really ${command.label.toLowerCase()}?` : command.label}
          onCancel={() => setConfirmStep(0)}
          testId="confirm-dialog"
          role="alertdialog"
          // Focus on Cancel when the question is asked (each step once), never on re-render.
          focusKey={confirmStep}
          actions={
            <>
              <Button onClick={() => setConfirmStep(0)} data-autofocus data-testid="confirm-keep">
                {dismiss}
              </Button>
              <Button
                variant={command.hazard === 'dangerous' || command.hazard === 'stop' ? 'danger' : 'primary'}
                data-testid="confirm-yes"
                data-stop={stop}
                onClick={() => {
                  if (command.confirmTwice && confirmStep === 1) setConfirmStep(2);
                  else void send();
                }}
              >
                {command.confirmTwice && confirmStep === 1
                  ? 'Continue'
                  : `Yes, ${command.label.toLowerCase()}`}
              </Button>
            </>
          }
        >
          <p>{confirmText}</p>
          {props.details}
          {confirmStep === 2 && (
            <p>
              <strong>This is the second confirmation.</strong>
            </p>
          )}
        </Dialog>
      )}
    </span>
  );
}

/** A machine's log: filter, pause, copy, download. */
export function LogView(props: { log: MachineLog; sources?: string[]; height?: number; testId?: string }) {
  const entries = useStore(props.log.store, (s) => s.entries);
  const [filter, setFilter] = useState('');
  const [paused, setPaused] = useState<LogEntry[] | null>(null);
  const shown = useMemo(() => {
    const src = paused ?? entries;
    const f = filter.trim().toLowerCase();
    return src.filter(
      (e) =>
        (!props.sources || props.sources.includes(e.source)) &&
        (!f || e.text.toLowerCase().includes(f) || e.source.includes(f)),
    );
  }, [entries, paused, filter, props.sources]);
  const asText = () =>
    shown.map((e) => `${new Date(e.at).toISOString()} ${e.level} ${e.source}: ${e.text}`).join('\n');
  return (
    <div data-testid={props.testId ?? 'log-view'}>
      <div className="ui-row" style={{ marginBottom: 8 }}>
        <input
          className="ui-input"
          placeholder="Filter"
          aria-label="Filter log"
          value={filter}
          onChange={(e) => setFilter(e.target.value)}
          style={{ flex: 1, minWidth: 160 }}
        />
        <Button small onClick={() => setPaused(paused ? null : entries)}>
          {paused ? 'Resume' : 'Pause'}
        </Button>
        <Button small onClick={() => void navigator.clipboard?.writeText(asText())}>
          Copy
        </Button>
        <Button small onClick={() => downloadText(`${props.log.machineId}-log.txt`, asText(), 'text/plain')}>
          Download
        </Button>
      </div>
      {/* The box scrolls; while it does it is a focusable region, so the keyboard can scroll it. */}
      <ScrollRegion className="ui-log" style={{ maxHeight: props.height ?? 420 }} label="Machine log">
        <div role="log" aria-live="polite" aria-label="Machine log">
          {shown.length === 0 && <div className="ui-muted">No entries.</div>}
          {shown.map((e) => (
            <div key={e.seq} className={`lv-${e.level}`}>
              <span className="t">{formatTime(e.at)}</span>
              <span className="src">{e.source}</span>
              {e.text}
            </div>
          ))}
        </div>
      </ScrollRegion>
    </div>
  );
}
