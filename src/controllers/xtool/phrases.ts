/**
 * The xTool status socket's frames (wire.ts) as people read them. The frame itself stays on the
 * page as a small subtitle for a technician, without its "ok:"/"err:" prefix ("xTool:
 * WORKING_ONLINE").
 */
const FRAME_WORDS: Record<string, string> = {
  'ok:IDLE': 'idle',
  'ok:WORKING_ONLINE': 'working on a job sent from a computer',
  'ok:WORKING_ONLINE_READY': 'job loaded, waiting for the button on the machine',
  'ok:WORKING_OFFLINE': 'working on a job started at the machine',
  'ok:WORKING_FRAMING': 'framing',
  'ok:WORKING_FRAME_READY': 'frame ready',
  'ok:PAUSING': 'paused',
  'ok:ERROR': 'error',
  WORK_STOPPED: 'job stopped',
  WORK_STOPED: 'job stopped',
  'ok:WORK_STOPPED': 'job stopped',
  'ok:WORK_STOPED': 'job stopped',
  'err:tiltCheck': 'tilt sensor tripped',
  'err:movingCheck': 'movement sensor tripped',
  'err:limitCheck': 'limit switch hit',
  'err:flameCheck': 'flame detected',
};

/** A frame in words; one the console does not know says so (never the raw text alone). */
export function frameWords(raw: string): string {
  return FRAME_WORDS[raw] ?? 'a message this console does not know';
}

/** The frame as the technician's subtitle: "WORKING_ONLINE" (no "ok:"), at most 40 characters. */
export function frameTerm(raw: string): string {
  return raw.replace(/^(ok|err):/, '').slice(0, 40);
}
