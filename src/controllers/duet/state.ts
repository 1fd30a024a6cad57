import type { StoreApi } from 'zustand/vanilla';
import { createSharedStore } from '../../fleet/kernel';
import type { ObjectModel } from './wire';

/**
 * The Duet session's store: what the socket (or the fallback poll) delivers and what the user
 * did on this page. It is a shared store (`createSharedStore`): every write keeps the previous
 * object for every deep-equal part, so views re-render only for what changed. On-demand reads
 * (folder listings, file info with thumbnails, the height map) are not kept here: they are
 * queries (`reads.ts`), bounded and refetched after the commands that change them.
 */

/** Temperature history points per heater (15 min at one point a second). */
export const HISTORY_POINTS = 900;
/** The history takes at most one point per heater this often. */
export const HISTORY_EVERY_MS = 1000;

export interface UploadState {
  id: number;
  name: string;
  path: string;
  loaded: number;
  total: number;
  status: 'uploading' | 'done' | 'failed' | 'cancelled';
  error: string | null;
}

export interface DuetState {
  model: ObjectModel | null;
  /**
   * Temperature history, one series per heater index: [ms, °C]. Kept only while a page shows the
   * machine's details (ingest.ts); empty on a fleet page.
   */
  history: Record<number, Array<readonly [number, number]>>;
  /** Codes typed into the console, newest last. */
  codeHistory: string[];
  needsPassword: boolean;
  /** The folder the Files tab shows (its listing is a query: `reads.ts`). */
  filesDir: string;
  uploads: UploadState[];
  /** Message box seqs the user closed locally (mode 0 has no button to answer). */
  dismissedBoxes: number[];
  /** Where the model comes from: the socket, or polling while the socket cannot be opened. */
  /** 'standalone': a Duet without an SBC, whose model is always polled (`rr_model`). */
  transport: 'socket' | 'polling' | 'standalone' | null;
  /** Why the socket is down (shown while polling). */
  socketProblem: string | null;
}

export interface CodeArgs {
  code: string;
  async?: boolean;
}

export function createDuetStore(): StoreApi<DuetState> {
  return createSharedStore<DuetState>(() => ({
    model: null,
    history: {},
    codeHistory: [],
    needsPassword: false,
    filesDir: '0:/gcodes',
    uploads: [],
    dismissedBoxes: [],
    transport: null,
    socketProblem: null,
  }));
}

/** The history with one more point per heater that has a sensor (series capped at HISTORY_POINTS). */
export function withHistoryPoint(
  history: DuetState['history'],
  m: ObjectModel,
  now: number,
): DuetState['history'] {
  const out = { ...history };
  m.heat.heaters.forEach((h, i) => {
    if (!h || h.current <= -273) return;
    const prev = out[i] ?? [];
    const next = prev.length >= HISTORY_POINTS ? prev.slice(prev.length - HISTORY_POINTS + 1) : prev.slice();
    next.push([now, h.current] as const);
    out[i] = next;
  });
  return out;
}
