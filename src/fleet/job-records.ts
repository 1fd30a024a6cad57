import { useSyncExternalStore } from 'react';
import type { ServerJobRecord } from './types';

/**
 * The server's job records as this page received them (issue 33 item 6), apart from their
 * formatter (job-facts.ts) so that the page's entry, which stores them (boot.ts), does not carry
 * the formatter: the pages that show jobs load it.
 */

/** A server record as this page received it: its start is `receivedAt - elapsedMs` (page clock). */
export interface ReceivedJobRecord {
  record: ServerJobRecord;
  receivedAt: number;
}

const records = new Map<string, ReceivedJobRecord | null>();
const listeners = new Set<() => void>();

/**
 * The server's job records as the page received them (`GET /api/machines`, at boot and on each
 * refresh): a machine absent from `next` keeps what it had; null: the server says no job.
 */
export function setJobRecords(next: ReadonlyMap<string, ServerJobRecord | null>, receivedAt: number): void {
  for (const [id, r] of next) records.set(id, r ? { record: r, receivedAt } : null);
  for (const fn of listeners) fn();
}

export function jobRecordOf(id: string): ReceivedJobRecord | null {
  return records.get(id) ?? null;
}

function subscribe(fn: () => void): () => void {
  listeners.add(fn);
  return () => listeners.delete(fn);
}

/** The server's job record of a machine as this page has it (re-renders when a refresh brings one). */
export function useJobRecord(id: string): ReceivedJobRecord | null {
  return useSyncExternalStore(subscribe, () => records.get(id) ?? null);
}
