import type { AnswerEnv } from './answers';
import type { LiveJob } from './reader';

/** The messages between the gateway's thread (reads.ts) and a read worker (read-worker.ts). */

export interface ReadJob {
  route: string;
  csv: boolean;
  /** The query string (`URLSearchParams` text). */
  params: string;
  env: AnswerEnv;
  /** The recorder's open jobs, by machine (an open job counts up to now). */
  live: Record<string, LiveJob>;
}

export type ToWorker =
  | { type: 'run'; id: number; file: string; job: ReadJob }
  /** The gateway wrote a chunk out (the client is reading): one more may come. */
  | { type: 'credit'; id: number }
  /** The client went away: stop reading, close the connection. */
  | { type: 'cancel'; id: number };

export type FromWorker =
  | { type: 'json'; id: number; status: number; text: string }
  | { type: 'csv-head'; id: number; name: string; truncated: boolean }
  | { type: 'chunk'; id: number; text: string }
  | { type: 'end'; id: number }
  | { type: 'error'; id: number; message: string }
  /** The job is over (answered, failed or cancelled) and its connection closed. */
  | { type: 'done'; id: number };

/** Chunks of an export in flight (sent, not yet written out) at most. */
export const CREDIT_WINDOW = 2;
/** An export's chunk: about this many characters. */
export const CHUNK_CHARS = 64 * 1024;
