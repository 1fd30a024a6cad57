import type { ServerWatch } from '../../src/fleet/types';
import { mostSevereAlarm } from '../../src/fleet/types';
import type { WatchJobRecord, WatchSummary } from '../../src/fleet/contract';
import type { ConfigService, SecretsService } from '../services';
import { sendJson } from '../http-util';
import { machineInfo } from '../machines';
import { createSimApi, SIM_API_PATH, simAuditPath, type SimServices } from '../sim-api';
import { createTemperaturesApi, TEMPERATURES_API_PATH, type TemperatureStore } from '../temperatures';
import { decodeSegment } from '../http-util';
import { DEFAULT_BODY_LIMIT, type ApiRoute, type RouteCall } from './route';

/**
 * The machines: the fleet's list with what the gateway's watch last read of each, a machine's
 * last minutes of temperatures, and the Simulator tab of a simulated machine (sim-api.ts).
 */

/** A machine's watch summary as `GET /api/machines` gives it (the fleet page's first screen). */
export interface Watched {
  summary: WatchSummary;
  /** When the watch last heard the machine (ms, the gateway's clock); null: not yet. */
  lastSeen: number | null;
  /** The job the watch keeps a record of (watch.ts `nextJobRecord`); null or absent: none. */
  job?: WatchJobRecord | null;
}

/** Longest text of a controller's the machines list carries (a job name, an alarm). */
const WATCH_TEXT_MAX = 200;

/**
 * The summary sent with a machine (`watch`): state, job, progress and alarm as the gateway's watch
 * last read them, and how long ago (its age, not a clock time: the tablet's clock may differ).
 * Controller text is scrubbed of the machine's secrets and cut short; the page escapes it.
 */
export function watchForPage(
  w: Watched | null,
  now: number,
  scrub: (text: string) => string,
): ServerWatch | undefined {
  if (!w) return undefined;
  const s = w.summary;
  const { state } = s;
  const text = (t: string | null): string | null => (t === null ? null : scrub(t).slice(0, WATCH_TEXT_MAX));
  // Answered, but not readable by the server (a web page for a model): said so, its age kept.
  if (s.unread && state !== 'offline')
    return {
      state: 'unread',
      job: null,
      progress: null,
      alarm: null,
      alarmSeverity: null,
      unread: text(s.unread),
      ageMs: w.lastSeen === null ? null : Math.max(0, now - w.lastSeen),
    };
  if (state === 'unknown') return undefined;
  return {
    state,
    job: text(s.job),
    progress: typeof s.progress === 'number' && s.progress >= 0 && s.progress <= 1 ? s.progress : null,
    alarm: text(s.alarm),
    // The worst of the alarms the watch read (a warning when it did not say).
    alarmSeverity: s.alarm === null ? null : (mostSevereAlarm(s.alarms ?? [])?.severity ?? 'warning'),
    ageMs: w.lastSeen === null ? null : Math.max(0, now - w.lastSeen),
    // The job record, every view's job facts: its start as an age (the tablet's clock may differ).
    record: w.job
      ? {
          name: text(w.job.name),
          elapsedMs: Math.max(0, now - w.job.startedAt),
          startSeen: w.job.startSeen,
          progress: w.job.progress,
        }
      : null,
  };
}

export type MachinesServices = Pick<ConfigService, 'config' | 'now' | 'builtInDemo'> &
  Pick<SecretsService, 'scrub'> &
  SimServices & {
    /** What the gateway's watch knows of a machine now; absent: nothing is watched. */
    watched?: (id: string) => Watched | null;
    /** Asks the watch of a machine to read it now; absent: nothing is watched. */
    lookNow?: (id: string) => void;
    temperatures: TemperatureStore;
  };

export function machinesRoutes(s: MachinesServices): ApiRoute[] {
  const { config, now, scrub, mayUseMachine, watched } = s;
  const simApi = createSimApi(s, s.lookNow);
  const temperaturesApi = createTemperaturesApi(s, s.temperatures);
  const sim = {
    path: SIM_API_PATH,
    example: '/api/sim/demo',
    role: 'supervisor',
    refusal: (p) => `the simulator is for supervisors (${p.name} is ${p.role})`,
    notAllowed: 'GET or POST',
    handle: (req, res, call) => simApi(req, res, call.params.id ?? '', call.principal),
  } satisfies Partial<ApiRoute>;
  /** A refused change to a simulator names its machine (a refused read is written with its path). */
  const simRefusal = (call: RouteCall) => {
    const id = decodeSegment(call.params.id ?? '');
    return { machine: s.byId.has(id) ? id : undefined, path: simAuditPath(id) };
  };
  return [
    {
      method: 'GET',
      path: '/api/machines',
      role: 'viewer',
      changesState: false,
      audited: false,
      handle(req, res, { principal: p }) {
        const t = now();
        const machines = config.machines
          .filter((m) => mayUseMachine(p, m.id))
          .map((m) => {
            const watch = watchForPage(watched?.(m.id) ?? null, t, scrub);
            return watch ? { ...machineInfo(m), watch } : machineInfo(m);
          });
        // `demo`: the built-in demo fleet (no machines file): the gateway runs demo jobs.
        sendJson(res, 200, { machines, demo: s.builtInDemo });
      },
    },
    {
      method: 'GET',
      path: TEMPERATURES_API_PATH,
      example: '/api/machines/demo/temperatures',
      role: 'viewer',
      changesState: false,
      audited: false,
      notAllowed: 'GET only',
      handle: (req, res, call) => temperaturesApi(req, res, call.url, call.params.id ?? '', call.principal),
    },
    { ...sim, method: 'GET', changesState: false, audited: false },
    {
      ...sim,
      method: 'POST',
      changesState: true,
      touch: true,
      bodyLimit: DEFAULT_BODY_LIMIT,
      audited: true,
      auditRefusal: simRefusal,
    },
  ];
}
