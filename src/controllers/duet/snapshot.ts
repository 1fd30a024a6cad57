import type { Activity, Alarm, JobSummary, MachineSnapshot, Temperature } from '../../fleet/types';
import { baseName } from './client';
import type { MachineStatus, ObjectModel } from './wire';

/** Words for every `state.status` value (DSF 3.5 MachineStatus), for the operator. */
export const STATUS_WORDS: Record<string, string> = {
  disconnected: 'Firmware not connected',
  starting: 'Starting',
  updating: 'Updating firmware',
  off: 'Power off',
  halted: 'Halted (emergency stop)',
  pausing: 'Pausing',
  paused: 'Paused',
  resuming: 'Resuming',
  cancelling: 'Cancelling',
  processing: 'Printing',
  simulating: 'Simulating',
  busy: 'Busy',
  changingTool: 'Changing tool',
  idle: 'Idle',
};

export function statusWords(status: MachineStatus): string {
  return STATUS_WORDS[status] ?? status;
}

/**
 * Normalized activity. Decisions: `pausing` counts as paused (the machine is on its way there and
 * must not be told to pause again); `cancelling` is stopping; `halted` and `disconnected` are
 * errors (emergency stop; DSF lost its firmware); `off` (ATX power off) is idle; `starting` and
 * `updating` are unknown (the machine cannot be used yet).
 */
export function activityOf(status: MachineStatus): Activity {
  switch (status) {
    case 'processing':
    case 'simulating':
    case 'busy':
    case 'changingTool':
    case 'resuming':
      return 'running';
    case 'pausing':
    case 'paused':
      return 'paused';
    case 'cancelling':
      return 'stopping';
    case 'halted':
    case 'disconnected':
      return 'error';
    case 'idle':
    case 'off':
      return 'idle';
    default:
      return 'unknown';
  }
}

export function isPrinting(status: MachineStatus): boolean {
  return ['processing', 'simulating', 'pausing', 'paused', 'resuming', 'cancelling'].includes(status);
}

/** Progress of the job: file position over file size (what Duet Web Control shows as "file" progress). */
export function jobProgress(m: ObjectModel): number | null {
  const size = m.job.file?.size ?? 0;
  const pos = m.job.filePosition;
  if (!m.job.file?.fileName || !size || pos === null) return null;
  return Math.max(0, Math.min(1, pos / size));
}

export function jobSummary(m: ObjectModel): JobSummary | null {
  const name = m.job.file?.fileName;
  if (!name || !isPrinting(m.state.status)) return null;
  const t = m.job.timesLeft;
  return {
    name: baseName(name),
    progress: jobProgress(m),
    elapsed: m.job.duration,
    // file-based estimate first (it follows the real progress), then filament, then slicer.
    remaining: t?.file ?? t?.filament ?? t?.slicer ?? null,
  };
}

export function heaterName(m: Pick<ObjectModel, 'heat' | 'tools'>, index: number): string {
  if (m.heat.bedHeaters.includes(index))
    return m.heat.bedHeaters.filter((h) => h >= 0).length > 1 ? `Bed ${index}` : 'Bed';
  if (m.heat.chamberHeaters.includes(index)) return 'Chamber';
  const tool = m.tools.find((t) => t && t.heaters.includes(index));
  if (tool) return tool.name ? `${tool.name} (T${tool.number})` : `Tool ${tool.number}`;
  return `Heater ${index}`;
}

export function temperatures(m: ObjectModel): Temperature[] {
  const out: Temperature[] = [];
  m.heat.heaters.forEach((h, i) => {
    if (!h) return;
    // No sensor reads -273.15 (the real geminiv2 model): show it as unknown, not as a temperature.
    const current = h.current <= -273 ? null : h.current;
    const target = h.state === 'active' ? h.active : h.state === 'standby' ? h.standby : null;
    out.push({ name: heaterName(m, i), current, target });
  });
  return out;
}

export function alarmsOf(m: ObjectModel, since: (id: string) => number): Alarm[] {
  const alarms: Alarm[] = [];
  if (m.state.status === 'halted') {
    alarms.push({
      id: 'halted',
      severity: 'critical',
      message: 'Emergency stop: the machine is halted',
      since: since('halted'),
      clears: 'reset (M999)',
    });
  }
  if (m.state.status === 'disconnected') {
    alarms.push({
      id: 'disconnected',
      severity: 'critical',
      message: 'DSF has lost the connection to the firmware board',
      since: since('disconnected'),
    });
  }
  m.heat.heaters.forEach((h, i) => {
    if (h?.state === 'fault') {
      const id = `heater-${i}-fault`;
      alarms.push({
        id,
        severity: 'critical',
        message: `Heater fault: ${heaterName(m, i)}`,
        since: since(id),
        clears: `reset the fault (M562 P${i})`,
      });
    }
  });
  const box = m.state.messageBox;
  if (box) {
    const id = `messagebox-${box.seq}`;
    alarms.push({
      id,
      severity: 'warning',
      message: `Message from the machine: ${box.title || box.message}`,
      since: since(id),
      clears: 'answer the message',
    });
  }
  return alarms;
}

/** The normalized snapshot fields of a Duet object model. */
export function snapshotOf(m: ObjectModel, since: (id: string) => number): Partial<MachineSnapshot> {
  const positions: Record<string, number> = {};
  for (const a of m.move.axes)
    if (a && a.visible && a.userPosition !== null) positions[a.letter] = a.userPosition;
  const board = m.boards[0];
  const identity = board
    ? [
        board.name ?? board.shortName,
        board.firmwareVersion ? `RRF ${board.firmwareVersion}` : null,
        m.sbc?.dsf?.version ? `DSF ${m.sbc.dsf.version}` : null,
      ]
        .filter(Boolean)
        .join(' · ')
    : null;
  const status = m.state.status;
  const job = jobSummary(m);
  let label = statusWords(status);
  // The job's name, not its percentage: that is the job line's, from the server's job record
  // (fleet/job-facts.ts), so a tile never shows two percentages of one job (issue 33).
  if (job && (status === 'processing' || status === 'simulating')) label = `${label} ${job.name}`;
  return {
    activity: activityOf(status),
    activityLabel: label,
    job,
    alarms: alarmsOf(m, since),
    positions,
    temperatures: temperatures(m),
    identity,
  };
}
