import type { FormModel } from '../../forms/model';
import type { PruntApi, PruntForm } from './config-ir';
import type { StatusModule, StatusValues } from './status';
import type { SmartPlug, StartupState, UpdateCheck } from './wire';

/**
 * The Prunt session's stores, as plain data: what the live socket and the connect-time reads
 * fill (`PruntState`) and what the config editor holds (`ConfigState`). Both are shared stores
 * (src/fleet/kernel/share.ts): an equal write keeps identities and notifies nobody.
 */

/** Status ticks are every 50 ms; the divisor asks for every Nth. */
export const TICK_MS = 50;
/** Fleet view: 1 per second. */
export const FLEET_DIVISOR = 20;
export const LIVE_RATES = [1, 2, 5, 10] as const;
/**
 * Prunt ticks at least once per second (the fleet divisor; faster on a machine page): this much
 * silence is a dead socket, so a silent link shows as down within 5 s (issue 15: it was 10 s,
 * and the page said "Online" 10 s into a silent network). Checked every 0.5 s.
 */
export const SILENCE_MS = 3000;

export function divisorFor(hz: number): number {
  const h = Math.min(10, Math.max(0.1, hz));
  return Math.max(1, Math.round(1000 / TICK_MS / h));
}

export interface GcodeEntry {
  seq: number;
  at: number;
  command: string;
  id: string | null;
  state: 'sending' | 'sent' | 'Running' | 'Completed' | 'Cancelled' | 'Failed' | 'error' | string;
  output: string[];
}

export interface PruntState {
  api: PruntApi | null;
  startTime: string | null;
  startup: StartupState | null;
  statusModel: StatusModule[] | null;
  status: StatusValues;
  statusAt: number | null;
  smartPlug: SmartPlug | null;
  exception: { message: string; fatal: boolean } | null;
  /** The controller's last update check (read on connect; 500 when it timed out). */
  update: { result: UpdateCheck | null; error: string | null } | null;
  gcode: GcodeEntry[];
  /** Ticks per second asked of the controller while a machine page watches (user-selectable). */
  liveHz: number;
  divisor: number;
}

export function initialPruntState(): PruntState {
  return {
    api: null,
    startTime: null,
    startup: null,
    statusModel: null,
    status: {},
    statusAt: null,
    smartPlug: null,
    exception: null,
    update: null,
    gcode: [],
    liveHz: 5,
    divisor: FLEET_DIVISOR,
  };
}

export interface ConfigState {
  phase: 'idle' | 'loading' | 'ready' | 'error';
  error: string | null;
  form: PruntForm | null;
  model: FormModel | null;
  /**
   * The editor's unsaved changes and whether any field is invalid, kept in step with the
   * model's own store, so "Save" availability reads this store alone.
   */
  pending: number;
  invalid: boolean;
  saving: boolean;
  lastSave: { at: number; saved: boolean; message: string } | null;
  /** A save went through: offer "reload the server to apply". */
  offerReload: boolean;
  /** Told after a server restart / schema change. */
  notice: string | null;
}

export function initialConfigState(): ConfigState {
  return {
    phase: 'idle',
    error: null,
    form: null,
    model: null,
    pending: 0,
    invalid: false,
    saving: false,
    lastSave: null,
    offerReload: false,
    notice: null,
  };
}
