import type { Activity, Alarm, JobSummary, Temperature } from '../../fleet/types';
import type { FlatStatusValues, ModuleStatusValues, StartupState, StatusSchemaWire } from './wire';

/**
 * One status model for both API generations: module → group → value with kind, unit,
 * description and Condition (when the value is present). The flat API has no modules and no
 * units: its groups go in one module, "Board", with units known from the group names
 * (prunt-web_server.adb `Build_Status_Schema`), and its scalars (Time, Startup, …) in "General".
 */

export interface StatusEntry {
  module: string;
  group: string;
  name: string;
  kind: string;
  unit: string;
  description: string;
  condition: string;
}

export interface StatusGroup {
  name: string;
  entries: StatusEntry[];
}

export interface StatusModule {
  name: string;
  groups: StatusGroup[];
}

export type StatusScalar = number | boolean | string | null;
export type StatusValues = Record<string, Record<string, Record<string, StatusScalar>>>;

export const FLAT_MODULE = 'Board';

const FLAT_GROUP_INFO: Record<string, { kind: string; unit: string; what: string }> = {
  Position: { kind: 'Real', unit: 'mm', what: 'Position of axis' },
  Thermistor_Temperatures: { kind: 'Real', unit: 'celsius', what: 'Temperature of thermistor' },
  Stepper_Temperatures: { kind: 'Real', unit: 'celsius', what: 'Temperature reported by stepper driver' },
  Board_Probe_Temperatures: { kind: 'Real', unit: 'celsius', what: 'Temperature of board probe' },
  Heater_Powers: { kind: 'Real', unit: '', what: 'Power output (0 to 1) of heater' },
  Heater_Currents: { kind: 'Real', unit: 'amp', what: 'Current through heater' },
  Switch_Is_High_State: { kind: 'Boolean', unit: '', what: 'Input is in its high state:' },
  Tachometer_Frequencies: { kind: 'Real', unit: 'hertz', what: 'Tachometer frequency of fan' },
  StallGuard_Values: { kind: 'Integer', unit: '', what: 'StallGuard reading of' },
};

const FLAT_SCALARS: StatusEntry[] = [
  { name: 'Current_File_Name', kind: 'String', unit: '', description: 'File being run (empty when idle).' },
  { name: 'Current_File_Line', kind: 'Integer', unit: '', description: 'Line of the file being run.' },
  { name: 'Stepgen_Is_Paused', kind: 'Boolean', unit: '', description: 'The step generator is paused.' },
  { name: 'Startup', kind: 'String', unit: '', description: 'Startup state of the server.' },
  { name: 'Time', kind: 'Real', unit: 's', description: 'Server time.' },
].map((e) => ({ ...e, module: FLAT_MODULE, group: 'General', condition: '' }));

export function buildStatusModel(wire: StatusSchemaWire): StatusModule[] {
  if (wire.api === 'flat') {
    const groups: StatusGroup[] = [{ name: 'General', entries: FLAT_SCALARS }];
    for (const [g, names] of Object.entries(wire.schema)) {
      const info = FLAT_GROUP_INFO[g] ?? { kind: 'Real', unit: '', what: g.replace(/_/g, ' ') };
      groups.push({
        name: g,
        entries: names.map((n) => ({
          module: FLAT_MODULE,
          group: g,
          name: n,
          kind: info.kind,
          unit: info.unit,
          description: `${info.what} ${n}`,
          condition: '',
        })),
      });
    }
    return [{ name: FLAT_MODULE, groups }];
  }
  return Object.entries(wire.schema).map(([m, groups]) => ({
    name: m,
    groups: Object.entries(groups).map(([g, entries]) => ({
      name: g,
      entries: Object.entries(entries).map(([n, e]) => ({
        module: m,
        group: g,
        name: n,
        kind: e.Kind,
        unit: e.Unit,
        description: e.Description,
        condition: e.Condition,
      })),
    })),
  }));
}

export function normalizeFlat(v: FlatStatusValues): StatusValues {
  const board: Record<string, Record<string, StatusScalar>> = { General: {} };
  for (const [k, x] of Object.entries(v)) {
    if (x !== null && typeof x === 'object') board[k] = x;
    else (board['General'] as Record<string, StatusScalar>)[k] = x;
  }
  return { [FLAT_MODULE]: board };
}

export function normalizeModule(v: ModuleStatusValues): StatusValues {
  return v;
}

/** What the fleet snapshot needs, from either generation. */
export interface Derived {
  positions: Record<string, number>;
  temperatures: Temperature[];
  /** Series for the live chart: "Thermistors · THERMISTOR_1" → value. */
  series: Record<string, number>;
  fileName: string | null;
  line: number | null;
  paused: boolean;
}

const SERIES_UNITS = new Set(['celsius', 'mm']);

export function derive(model: readonly StatusModule[], values: StatusValues): Derived {
  const positions: Record<string, number> = {};
  const temperatures: Temperature[] = [];
  const series: Record<string, number> = {};
  let fileName: string | null = null;
  let line: number | null = null;
  let paused = false;
  for (const m of model) {
    for (const g of m.groups) {
      for (const e of g.entries) {
        const v = values[m.name]?.[g.name]?.[e.name];
        if (v === undefined || v === null) continue;
        if (typeof v === 'number') {
          if (g.name === 'Position') positions[e.name.replace(/_AXIS$/, '')] = v;
          if (e.unit === 'celsius' && g.name !== 'Stepper_Temperatures')
            temperatures.push({ name: e.name, current: v, target: null });
          const isPower = /power/i.test(g.name);
          if (SERIES_UNITS.has(e.unit) || isPower) series[`${g.name} · ${e.name}`] = v;
        }
        const n = e.name.toLowerCase();
        if ((n === 'current_file_name' || n === 'file name') && typeof v === 'string') fileName = v || null;
        if ((n === 'current_file_line' || n === 'current line') && typeof v === 'number') line = v;
        if ((n === 'stepgen_is_paused' || n === 'paused') && typeof v === 'boolean') paused = v;
      }
    }
  }
  return { positions, temperatures, series, fileName, line, paused };
}

export function activityOf(
  d: Derived,
  startup: StartupState | null,
  exception: { message: string; fatal: boolean } | null,
): { activity: Activity; label: string } {
  if (exception?.fatal) return { activity: 'error', label: `Server error: ${exception.message.trim()}` };
  if (startup === 'Update_Required') return { activity: 'alarm', label: 'Firmware update required' };
  if (startup === 'Update_Running') return { activity: 'unknown', label: 'Firmware update running' };
  if (startup === 'Waiting') return { activity: 'unknown', label: 'Starting up' };
  if (startup && startup.startsWith('unknown')) return { activity: 'unknown', label: `Startup: ${startup}` };
  const name = d.fileName ? d.fileName.replace(/^uploads\//, '') : null;
  if (name && d.paused)
    return { activity: 'paused', label: `Paused: ${name}${d.line !== null ? ` · line ${d.line}` : ''}` };
  if (name)
    return { activity: 'running', label: `Running ${name}${d.line !== null ? ` · line ${d.line}` : ''}` };
  if (d.paused) return { activity: 'paused', label: 'Paused (idle)' };
  return { activity: 'idle', label: 'Idle' };
}

export function alarmsOf(
  startup: StartupState | null,
  exception: { message: string; fatal: boolean } | null,
  since: (id: string) => number,
): Alarm[] {
  const alarms: Alarm[] = [];
  if (startup === 'Update_Required') {
    alarms.push({
      id: 'firmware-update-required',
      severity: 'warning',
      message: 'Firmware update required: a supervisor must allow it before the machine can start.',
      since: since('firmware-update-required'),
      clears: 'allow firmware update',
    });
  }
  if (exception) {
    alarms.push({
      id: `server-exception-${exception.fatal ? 'fatal' : 'recoverable'}`,
      severity: exception.fatal ? 'critical' : 'warning',
      message: `Server exception: ${exception.message.trim()}`,
      since: since(`server-exception-${exception.fatal ? 'fatal' : 'recoverable'}`),
      clears: exception.fatal ? 'reload the server' : 'clears itself',
    });
  }
  return alarms;
}

export function jobOf(d: Derived, startedAt: number | null, now: number): JobSummary | null {
  if (!d.fileName) return null;
  // Prunt reports the line, not the file length: progress and remaining time are unknown.
  return {
    name: d.fileName.replace(/^uploads\//, ''),
    progress: null,
    elapsed: startedAt === null ? null : Math.max(0, Math.round((now - startedAt) / 1000)),
    remaining: null,
  };
}
