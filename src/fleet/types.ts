/**
 * Vendor-neutral vocabulary of the console. Everything here is plain data: it is shared by the
 * browser, the gateway (Node) and the simulators.
 */

/**
 * The kinds of machine, one per controller family. Each family adds its own in its manifest
 * (`src/controllers/<kind>/manifest.ts`, by declaration merging: `declare module
 * '../../fleet/types' { interface MachineKinds { xtool: true } }`), so this layer names no
 * family and imports none, and `MachineKind` is still the union of the families' kinds. The
 * list of them at run time is the registry's (`MACHINE_KINDS` in src/controllers/index.ts; the
 * gateway's from src/controllers/families.ts).
 */
// eslint-disable-next-line @typescript-eslint/no-empty-object-type -- filled by the families' manifests
export interface MachineKinds {}
export type MachineKind = keyof MachineKinds & string;

/**
 * Which API a machine speaks, where its family has more than one (the machines file's optional
 * `api`, Duet only): DSF (`/machine/*`, a Duet with an SBC) or standalone RepRapFirmware (`rr_*`).
 * Absent: learned when the gateway opens the session.
 */
export const MACHINE_APIS = ['dsf', 'standalone'] as const;
export type MachineApi = (typeof MACHINE_APIS)[number];

/** What the browser learns about a machine from `GET /api/machines`: nothing secret. */
export interface MachineInfo {
  id: string;
  name: string;
  kind: MachineKind;
  simulated: boolean;
  /** Where it stands (a bay, a room), from the machines file's optional `group`. */
  group?: string;
  /**
   * What the console server's watch last read of it, sent with the machines list: the fleet
   * page's first screen before its session answers (src/app/first-screen.ts).
   */
  watch?: ServerWatch;
}

/** A machine's state as the console server's watch last read it (`watch` in `GET /api/machines`). */
export interface ServerWatch {
  /** `unread`: the machine answered the server's watch with nothing it can read (`unread` says why). */
  state: 'running' | 'paused' | 'idle' | 'alarm' | 'offline' | 'unread';
  job: string | null;
  /** 0..1 */
  progress: number | null;
  alarm: string | null;
  alarmSeverity?: AlarmSeverity | null | undefined;
  /** How long before the list was sent (ms): an age, not a clock time. */
  ageMs: number | null;
  /** Why the server cannot read it (state `unread`). */
  unread?: string | null | undefined;
  /** The server's job record (null or absent: no job): the one source of every view's job facts. */
  record?: ServerJobRecord | null | undefined;
}

/** The console server's record of a machine's job, as `GET /api/machines` sends it. */
export interface ServerJobRecord {
  name: string | null;
  /** How long the job had run (since the server first saw it) when the list was sent (ms). */
  elapsedMs: number;
  /** The server saw it start (false: it was already under way at the server's first reading). */
  startSeen: boolean;
  /** 0..1, null when unknown */
  progress: number | null;
}

export const ROLES = ['viewer', 'operator', 'supervisor'] as const;
export type Role = (typeof ROLES)[number];

export function roleAtLeast(have: Role, need: Role): boolean {
  return ROLES.indexOf(have) >= ROLES.indexOf(need);
}

/** Hazard classes of DESIGN.md, principle 4. */
export type Hazard = 'read' | 'adjust' | 'motion' | 'job' | 'stop' | 'dangerous';

/** State of the link between the console and one controller. */
export type LinkState =
  'connecting' | 'online' | 'reconnecting' | 'needs-login' | 'protocol-error' | 'offline';

/** Normalized activity: what the machine is doing, for fleet views. */
export type Activity = 'offline' | 'idle' | 'running' | 'paused' | 'stopping' | 'error' | 'alarm' | 'unknown';

export type AlarmSeverity = 'info' | 'warning' | 'critical';

export interface Alarm {
  /** Stable within a machine: the same condition keeps the same id while it lasts. */
  id: string;
  severity: AlarmSeverity;
  message: string;
  /** ms since epoch */
  since: number;
  /** Critical alarms that block every page until acknowledged (xTool flame). */
  blocking?: boolean;
  acknowledged?: boolean;
  /** What clears it, in words ("clear alarm", "power cycle"). */
  clears?: string;
}

export interface JobSummary {
  name: string | null;
  /** 0..1, null when unknown */
  progress: number | null;
  /** seconds */
  elapsed: number | null;
  /** seconds */
  remaining: number | null;
}

export interface Temperature {
  name: string;
  current: number | null;
  target: number | null;
}

export interface LinkProblem {
  /** network | timeout | http | protocol | vendor | auth */
  kind: string;
  message: string;
  /** zod issue path for protocol errors, e.g. "progress.working" */
  path?: string;
}

export interface MachineSnapshot {
  id: string;
  link: LinkState;
  /** When link is reconnecting: when the next attempt is due (ms since epoch). */
  retryAt: number | null;
  problem: LinkProblem | null;
  activity: Activity;
  /** Vendor words for the activity ("Job loaded — press the button on the machine"). */
  activityLabel: string;
  job: JobSummary | null;
  alarms: Alarm[];
  positions: Record<string, number>;
  temperatures: Temperature[];
  /** ms since epoch of the last good data from the controller. */
  updatedAt: number | null;
  /** Short model / firmware line ("xTool D1Pro · V40.31.006.01 B2"). */
  identity: string | null;
}

export function emptySnapshot(id: string): MachineSnapshot {
  return {
    id,
    link: 'connecting',
    retryAt: null,
    problem: null,
    activity: 'unknown',
    activityLabel: 'Connecting…',
    job: null,
    alarms: [],
    positions: {},
    temperatures: [],
    updatedAt: null,
    identity: null,
  };
}

/** Alarm severities in order: the page, the alarm centre and the machines list rank by it. */
export const SEVERITY_RANK: Record<AlarmSeverity, number> = { info: 0, warning: 1, critical: 2 };

export function mostSevereAlarm<T extends { severity: AlarmSeverity }>(alarms: readonly T[]): T | null {
  let best: T | null = null;
  for (const a of alarms) {
    if (!best || SEVERITY_RANK[a.severity] > SEVERITY_RANK[best.severity]) best = a;
  }
  return best;
}

export const MACHINE_ID = /^[a-z0-9-]{1,40}$/;
