import type { MachineSnapshot } from '../../fleet/types';
import { INITIAL_STATE, jobSummary, stateLabel, toActivity, type MachineState } from './state';
import type { PeripheryStatus, Progress, WorkingSta } from './wire';

/**
 * The data of one xTool laser as the session keeps it (the `detail` store), and the pure
 * mappings from it: the job name rule and the fields of the machine snapshot. No I/O here.
 */

export interface Identity {
  type: string | null;
  power: number | null;
  powerInfoType: number | null;
  version: string | null;
  sn: string | null;
  mac: string | null;
  name: string | null;
}

export interface UploadState {
  name: string;
  path: string;
  loaded: number;
  total: number;
  phase: 'uploading' | 'verifying' | 'done' | 'failed';
  message: string | null;
}

export interface ConsoleEntry {
  at: number;
  code: string;
  ok: boolean;
  reply: string;
}

/**
 * The settings read on demand (`/peripherystatus`, `offset`, `dotMode`): one answer of the query
 * layer (queries.ts), shown by the Safety tab.
 */
export interface XtoolSettings {
  periphery: PeripheryStatus | null;
  offset: { x: number; y: number } | null;
  dotMode: number | null;
}

/** Vendor detail of one laser, beside the normalized snapshot. */
export interface XtoolDetail {
  model: { family: 'unknown' | 'd-series' | 'unsupported'; answered: string[] };
  identity: Identity;
  machine: MachineState;
  /** Where the current state came from. */
  source: 'poll' | 'socket' | 'command' | null;
  lastFrame: { raw: string; at: number } | null;
  working: WorkingSta | null;
  progress: Progress | null;
  /**
   * The last `/peripherystatus` the settings read got (queries.ts writes it here too): the SD card
   * decides whether an upload is possible, and availability reads only stores, never the query
   * cache. The Safety tab shows the query's answer itself.
   */
  periphery: PeripheryStatus | null;
  upload: UploadState | null;
  upgrade: UploadState | null;
  console: ConsoleEntry[];
  socketOpen: boolean;
  /** The name of the job we uploaded or started, when we know it. */
  jobName: string | null;
  /** A plain sentence for the operator after an upload ("press the button on the machine"). */
  notice: string | null;
}

const EMPTY_IDENTITY: Identity = {
  type: null,
  power: null,
  powerInfoType: null,
  version: null,
  sn: null,
  mac: null,
  name: null,
};

export function initialDetail(): XtoolDetail {
  return {
    model: { family: 'unknown', answered: [] },
    identity: EMPTY_IDENTITY,
    machine: INITIAL_STATE,
    source: null,
    lastFrame: null,
    working: null,
    progress: null,
    periphery: null,
    upload: null,
    upgrade: null,
    console: [],
    socketOpen: false,
    jobName: null,
    notice: null,
  };
}

/**
 * The job name to show after a state change. The laser never names its job: a name we learnt (our
 * upload, our remote start) is forgotten once the laser is idle, so the next job started from the
 * vendor app is not shown under the old name. A job loaded by software is the uploaded
 * /tmp.gcode (document: "Type 1 = /tmp.gcode"), so that is its name when we know no better.
 */
export function jobNameAfter(name: string | null, m: MachineState): string | null {
  if (m.state === 'idle' || m.state === 'alarm' || m.state === 'error') return null;
  if (name === null && m.state === 'job-loaded') return 'tmp.gcode';
  return name;
}

/** "xTool D1Pro · 10 W · V40.31.006.01 B2", or null before anything is known. */
export function identityLine(id: Identity): string | null {
  const parts = [id.type, id.power !== null ? `${id.power} W` : null, id.version].filter((p) => p);
  return parts.length ? parts.join(' · ') : null;
}

/** The snapshot fields that follow the laser's state: activity, its label, the job. */
export function snapshotOf(d: XtoolDetail): Partial<MachineSnapshot> {
  return {
    activity: toActivity(d.machine.state),
    activityLabel: stateLabel(d.machine),
    job: jobSummary(d.machine, d.progress, d.jobName),
  };
}

/** The folder of an SD card path ("/jobs/a.gcode" → "/jobs", "/tmp.gcode" → "/"). */
export function parentDir(path: string): string {
  const i = path.lastIndexOf('/');
  return i <= 0 ? '/' : path.slice(0, i);
}
