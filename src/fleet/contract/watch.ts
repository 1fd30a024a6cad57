import type { Activity, Alarm, AlarmSeverity } from '../types';
import type { JsonRecord } from './streams';

/** The slow watch the gateway keeps on each machine: its summaries, alarms, job and temperatures. */

/** One alarm or message as the watch sees it (the alarm centre's record is made of these). */
export interface WatchAlarm {
  /** Stable per condition within a machine: the id of the console's own alarm (`xtool-flame`). */
  key: string;
  severity: AlarmSeverity;
  text: string;
  /** Blocks every page until acknowledged (an xTool flame): the family's `Alarm.blocking`. */
  blocking?: boolean;
}

/** The summary of a machine the gateway's watch keeps (state and alarms, for audit and history). */
export interface WatchSummary {
  /** `offline`: the watch cannot reach the machine (set by the watch itself, never by a family). */
  state: 'running' | 'paused' | 'idle' | 'alarm' | 'offline' | 'unknown';
  /** The alarm in words when one is active. */
  alarm: string | null;
  /** The job's file or program name when one is known. */
  job: string | null;
  /**
   * Every alarm and message active now, with its severity (the alarm centre). Absent: the family
   * did not say (the alarm centre keeps what it had).
   */
  alarms?: WatchAlarm[];
  /**
   * The keys a frame raised as a new event in this summary (a flame sent by the laser): a new
   * occurrence even while an acknowledged record of the same key is still open. Set by the watch.
   */
  raised?: string[];
  /**
   * How far the job is, 0..1, when the family's watch reads it (TouchCut, Duet); absent or null
   * when unknown. The job history keeps the last value a job had.
   */
  progress?: number | null;
  /**
   * Why the watch could not read the machine's answer (it answered, but not what the family reads:
   * a web page, a 404, a model that does not validate): the machine is "not read by the server",
   * its last reading no longer current. Null or absent: read. Set by the watch, never by a family.
   */
  unread?: string | null;
}

/**
 * The console server's record of a machine's job (issue 33): one per machine, kept by its watch
 * from the summaries it learns, the one source of every view's job facts (name, start, elapsed,
 * progress). Null while no job runs.
 */
export interface WatchJobRecord {
  /** The job's name as the server knows it (the summary's, kept once learnt); null: none known. */
  name: string | null;
  /** When the server first saw the job running or paused (ms, the server's clock). */
  startedAt: number;
  /**
   * Whether the server saw the job start (the machine was idle before): false when its first
   * reading already found it under way (the server started mid-job), so the job is older than that.
   */
  startSeen: boolean;
  /** 0..1, null when unknown. */
  progress: number | null;
}

/** What a frame of a watched stream says: part of a summary, and alarms it raised (a frame cannot clear). */
export type WatchNews = Partial<WatchSummary> & { raise?: WatchAlarm[] };

/** A family's own alarms (the same ids and words as on its pages) as the watch records them. */
export function watchAlarmsOf(alarms: readonly Alarm[]): WatchAlarm[] {
  return alarms.map((a) => ({
    key: a.id,
    severity: a.severity,
    text: a.message,
    ...(a.blocking ? { blocking: true } : {}),
  }));
}

/** A machine's activity as the watch records it (the same reading for every family). */
export function watchStateOf(a: Activity): WatchSummary['state'] {
  switch (a) {
    case 'running':
    case 'stopping':
      return 'running';
    case 'paused':
      return 'paused';
    case 'idle':
      return 'idle';
    case 'alarm':
    case 'error':
      return 'alarm';
    case 'offline':
    case 'unknown':
      return 'unknown';
  }
}

/**
 * The slow watch the gateway keeps on a machine nobody looks at: one read every `everyMs`
 * (`path`), or the shared stream kept open (`stream`: its path) and its frames read.
 */
export interface WatchDecl {
  everyMs: number;
  /** A read (GET `path`) whose answer `read` turns into a summary. */
  poll?: {
    path: string;
    /**
     * The summary, or the part the answer tells (a field left out: the watch keeps what it knew).
     * `known`: what the watch knew before this answer (an answer that cannot tell two states apart).
     */
    read(status: number, body: string, known?: WatchSummary): WatchSummary | WatchNews | Error;
  };
  /** A shared stream kept open while the watch runs; `read` turns its frames into summaries (null: no news). */
  stream?: { path: string; read(frame: string): WatchNews | null };
  /**
   * The temperatures the gateway keeps for the charts (gateway/temperatures.ts), read from what
   * the watch already reads (no read of their own): the poll's answer, a frame of the stream, or
   * the merged model of a model stream. Null: nothing read for certain. Never throws.
   */
  temperatures?: TemperatureDecl;
  /**
   * A second read made after a poll that found a job running or paused, when the poll's answer
   * names no job (g2core: the status report does not, `GET /job` does): its news (job name,
   * progress) join the summary; an error or null adds nothing.
   */
  jobPoll?: { path: string; read(status: number, body: string): WatchNews | null };
}

/** One sensor's reading as a family reads it (untrusted: the gateway checks and bounds it). */
export interface TemperatureReading {
  /** Stable per sensor within a machine (Duet: the heater index; Prunt: "group · name"). */
  key: string;
  /** What the chart calls it ("Bed", "Tool 0"). */
  name: string;
  /** °C; null: no sensor or no reading now. */
  value: number | null;
}

export interface TemperatureDecl {
  fromPoll?(path: string, status: number, body: string): TemperatureReading[] | null;
  fromFrame?(frame: string): TemperatureReading[] | null;
  fromModel?(model: JsonRecord): TemperatureReading[] | null;
}
