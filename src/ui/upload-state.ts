/**
 * One upload's state, the same for every family: idle → uploading (progress) → verifying (some
 * controllers answer "ok" whatever happened, so the console looks) → done | failed | cancelled.
 * Plain data (no React), so sessions can hold it; the state machine that moves it is
 * `UploadTracker` in src/fleet/upload.ts, the UI that shows it `UploadStatus`.
 */
export interface UploadInfo {
  /** The file's name as the user picked it. */
  name: string;
  /** Where it goes on the controller ("0:/gcodes/part.gcode", "/tmp.gcode"), when worth saying. */
  target: string | null;
  /** Bytes sent and to send (total 0: unknown). */
  loaded: number;
  total: number;
}

export type UploadState =
  | { phase: 'idle' }
  | (UploadInfo & { phase: 'uploading' | 'verifying' })
  | (UploadInfo & { phase: 'done'; message: string | null })
  | (UploadInfo & { phase: 'failed'; message: string })
  | (UploadInfo & { phase: 'cancelled' });

export type UploadPhase = UploadState['phase'];

export const UPLOAD_IDLE: UploadState = { phase: 'idle' };

/** Whether the upload is still under way (the transfer or its verification). */
export function uploadActive(s: UploadState): boolean {
  return s.phase === 'uploading' || s.phase === 'verifying';
}
