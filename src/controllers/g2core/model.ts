import type { Activity, Alarm, JobSummary, MachineSnapshot } from '../../fleet/types';
import { STAT_ALARM, STAT_INTERLOCK, STAT_PANIC, STAT_SHUTDOWN, statLabel, statusText } from './codes';
import type { Job, Operation, Scalar, SrValues, VersionInfo } from './wire';

/**
 * The g2core family's data: what the session keeps (G2Detail, SettingsState) and the pure
 * mapping from it to the machine snapshot and to what the commands act on. No I/O here.
 */

export const AXIS_LETTERS = ['x', 'y', 'z', 'a', 'b', 'c'] as const;
export type AxisLetter = (typeof AXIS_LETTERS)[number];

/** The states in which the machine moves (or holds in the middle of a move). */
export const MOVING = new Set([5, 6, 7, 8, 9, 10, 11]);
/** Idle states: commands that start motion are available. */
export const IDLE = new Set([1, 3, 4]);

export interface TrackedOp {
  id: string;
  /** What the console started it for ("jog X+10", "MDI", "home"). */
  purpose: 'jog' | 'home' | 'mdi' | 'clear' | 'other';
  label: string;
  lines: string[];
  op: Operation | null;
  startedAt: number;
}

export interface ConsoleEntry {
  seq: number;
  at: number;
  lines: string[];
  opId: string | null;
  state: 'sent' | 'running' | 'done' | 'error' | 'refused';
  /** Status text on error ("Gcode command unsupported — G999 (status 131)"). */
  message: string | null;
}

export interface G2Detail {
  version: VersionInfo | null;
  /** Merged status values (from filtered reports). */
  sr: SrValues;
  /** Axes whose mode (am) is not 0; x, y, z until known. */
  axes: AxisLetter[];
  overrides: { mfoe: boolean | null; ssoe: boolean | null };
  /** The job list as last read (through the query layer, key `['jobs']`). */
  jobs: Job[];
  ops: Record<string, TrackedOp>;
  /** False once the server said it has no `GET /operation` (404/405): settled point 8 in client.ts. */
  opsList: boolean;
  console: ConsoleEntry[];
  /** A sentence for the operator after a command ("Job queued"). */
  notice: string | null;
  /** The last error the controller reported (a job or an operation): in the alarm's words. */
  lastError: string | null;
}

/**
 * What the console keeps about settings besides the values themselves (those are on-demand
 * reads: queries.ts): the outcome of each write.
 */
export interface SettingsState {
  /** Per field "group.key": the refusal text of the last attempt. */
  fieldErrors: Record<string, string>;
  /** Keys the controller refused as read-only (status 104) — shown as such from then on. */
  refusedReadOnly: Record<string, true>;
  saved: Record<string, number>;
}

export function initialDetail(): G2Detail {
  return {
    version: null,
    sr: {},
    axes: ['x', 'y', 'z'],
    overrides: { mfoe: null, ssoe: null },
    jobs: [],
    ops: {},
    opsList: true,
    console: [],
    notice: null,
    lastError: null,
  };
}

export function initialSettings(): SettingsState {
  return { fieldErrors: {}, refusedReadOnly: {}, saved: {} };
}

export interface JogArgs {
  axis: AxisLetter;
  distance: number;
  feed: number;
}

export interface SettingArgs {
  group: string;
  key: string;
  value: unknown;
}

export const num = (v: Scalar | undefined): number | null =>
  typeof v === 'number' && Number.isFinite(v) ? v : null;

/** The machine state (stat) while the link is up; null when unknown or offline. */
export function statOf(snap: MachineSnapshot, d: G2Detail): number | null {
  return snap.link === 'online' ? num(d.sr.stat) : null;
}

/** stat → normalized activity (stat is the only state a UI should rely on: state-enums.json). */
export function activityOf(stat: number | null): Activity {
  switch (stat) {
    case 1:
    case 3:
    case 4:
      return 'idle';
    case 2:
    case 12:
    case 13:
      return 'alarm';
    case 5:
    case 7:
    case 8:
    case 9:
    case 10:
      return 'running';
    case 6:
    case 11:
      return 'paused';
    default:
      return 'unknown';
  }
}

/** What each stopping state means and what clears it (firmware table: 204/205 "$clear", 206 "^x"). */
export function alarmsOf(stat: number | null, since: number, lastError: string | null): Alarm[] {
  const why = lastError ? ` Last error: ${lastError}.` : '';
  if (stat === STAT_ALARM) {
    return [
      {
        id: 'g2core-alarm',
        severity: 'critical',
        message: `ALARM: the machine stopped (limit switch, soft limit or an alarm command) and rejects commands.${why}`,
        since,
        clears: 'Clear alarm (after checking the machine); position may be lost — home again',
      },
    ];
  }
  if (stat === STAT_SHUTDOWN) {
    return [
      {
        id: 'g2core-shutdown',
        severity: 'critical',
        message: `SHUTDOWN: an external shutdown (e-stop input) stopped the machine.${why}`,
        since,
        clears: 'Release the shutdown input, then Clear alarm; or reset the controller',
      },
    ];
  }
  if (stat === STAT_PANIC) {
    return [
      {
        id: 'g2core-panic',
        severity: 'critical',
        message: `PANIC: the controller detected an internal fault and will not process commands.${why}`,
        since,
        clears: 'Reset (^X / reset button) or power cycle the controller — Clear alarm does not work',
      },
    ];
  }
  if (stat === STAT_INTERLOCK) {
    return [
      {
        id: 'g2core-interlock',
        severity: 'warning',
        message: 'Safety interlock is open: motion is held.',
        since,
        clears: 'Close the interlock, then Cycle start',
      },
    ];
  }
  return [];
}

export function runningJob(jobs: readonly Job[]): Job | undefined {
  return jobs.find((j) => j.state.state === 'running' || j.state.state === 'paused');
}

export function jobSummary(jobs: readonly Job[], now: number): JobSummary | null {
  const j = runningJob(jobs);
  if (!j) return null;
  // Clamped: a server's `done` may be negative or beyond `lines`.
  const progress =
    j.lines && j.lines > 0 && typeof j.done === 'number' ? Math.min(1, Math.max(0, j.done / j.lines)) : null;
  const elapsed = j.started !== null ? Math.max(0, (now - j.started) / 1000) : null;
  const remaining =
    progress !== null && progress > 0.02 && elapsed !== null
      ? Math.round((elapsed * (1 - progress)) / progress)
      : null;
  return { name: j.name ?? `job ${j.id}`, progress, elapsed, remaining };
}

/** The snapshot's words for the state: "Run · part.nc" while a job moves the machine. */
export function activityLabelOf(stat: number | null, jobs: readonly Job[]): string {
  const running = runningJob(jobs);
  const label = statLabel(stat);
  return running && stat !== null && MOVING.has(stat)
    ? `${label} · ${running.name ?? `job ${running.id}`}`
    : label;
}

export function positionsOf(d: G2Detail): Record<string, number> {
  const positions: Record<string, number> = {};
  for (const a of d.axes) {
    const v = num(d.sr[`pos${a}`]);
    if (v !== null) positions[a.toUpperCase()] = v;
  }
  return positions;
}

/** Enabled axes (mode `am` not 0) and override switches from `GET /machine?filter=…`. */
export function machineInfoOf(tree: Record<string, unknown>): Pick<G2Detail, 'axes' | 'overrides'> {
  const axes = AXIS_LETTERS.filter((a) => {
    const g = tree[a];
    return typeof g === 'object' && g !== null && 'am' in g && typeof g.am === 'number' && g.am !== 0;
  });
  const flag = (v: unknown) => (typeof v === 'number' ? v === 1 : typeof v === 'boolean' ? v : null);
  return {
    axes: axes.length > 0 ? axes : ['x', 'y', 'z'],
    overrides: { mfoe: flag(tree.mfoe), ssoe: flag(tree.ssoe) },
  };
}

export function finished(op: Operation | null): boolean {
  const s = op?.opstate.state;
  return s === 'done' || s === 'error';
}

export function pruneOps(ops: Record<string, TrackedOp>): Record<string, TrackedOp> {
  const list = Object.values(ops);
  if (list.length <= 50) return ops;
  const keep = list.sort((a, b) => b.startedAt - a.startedAt).slice(0, 50);
  return Object.fromEntries(keep.map((t) => [t.id, t]));
}

export type Target = { kind: 'job' | 'op'; id: string; label: string };

/** The operation a feedhold / cycle start / kill acts on: the running job's, else ours. */
export function activeTarget(d: G2Detail): Target | null {
  const job = runningJob(d.jobs);
  if (job) return { kind: 'job', id: job.id, label: `job "${job.name ?? job.id}"` };
  // The operation in motion (or held) first, else the oldest unfinished one.
  const rank = (t: TrackedOp) => (t.op?.opstate.state === 'run' || t.op?.opstate.state === 'pause' ? 0 : 1);
  const ops = Object.values(d.ops)
    .filter((t) => !finished(t.op))
    .sort((a, b) => rank(a) - rank(b) || a.startedAt - b.startedAt);
  const op = ops[0];
  return op ? { kind: 'op', id: op.id, label: op.label } : null;
}

/** A jog or homing of this console that has not finished. */
export function activeJog(d: G2Detail): TrackedOp | null {
  return (
    Object.values(d.ops).find((t) => (t.purpose === 'jog' || t.purpose === 'home') && !finished(t.op)) ?? null
  );
}

/** Relative jog lines. Kill behaves like M30 (distance mode back to G90), so a stopped jog never leaves G91 behind. */
export function jogLines(a: JogArgs): string[] {
  const d = Number(a.distance.toFixed(4));
  const f = Math.max(1, Math.round(a.feed));
  return [`G91 G1 ${a.axis.toUpperCase()}${d} F${f}`, 'G90'];
}

export function omit<T>(r: Record<string, T>, k: string): Record<string, T> {
  const c = { ...r };
  delete c[k];
  return c;
}

/** A g2core status in words: the firmware text, the additional description, the code. */
export function describeStatus(s: {
  code: number;
  description?: string | undefined;
  additional_description?: string | null | undefined;
}): string {
  const add = s.additional_description ? ` — ${s.additional_description}` : '';
  const t = statusText(s.code);
  const text = t.startsWith('Status ') && s.description ? s.description : t;
  return `${text}${add} (status ${s.code})`;
}

export function identityOf(v: VersionInfo | null): string | null {
  if (!v) return null;
  const build = v.fbs || (v.fb !== undefined ? String(v.fb) : null);
  const hw = typeof v.hp === 'string' ? v.hp : v.hp !== undefined ? `platform ${v.hp}` : null;
  return ['g2core', build && `build ${build}`, hw].filter(Boolean).join(' · ');
}

export function formatPercent(v: unknown): string {
  return typeof v === 'number' ? `${Math.round(v * 100)} %` : String(v);
}
