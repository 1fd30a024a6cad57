import type http from 'node:http';
import type { IncomingMessage, ServerResponse } from 'node:http';
import type { SharingHints } from '../src/fleet/contract';
import type { HeldHttp } from './held-types';
import type { MachineEntry } from './machines';

/** The shared upstream's (upstream-http.ts) limits, counters and calls. */

export interface UpstreamLimits {
  /** Largest answer kept and replayed; larger ones are streamed to the waiters already joined. */
  maxSharedBytes: number;
  /** Reads waiting for a slot, per machine; one more is answered 503. */
  maxQueuedReads: number;
  /** Longest wait for a slot, ms (default: the gateway's timeout towards a controller). */
  queueTimeoutMs?: number;
  /** Kept answers per machine. */
  maxCachedAnswers: number;
  /** Bytes of kept answers per machine. */
  maxCachedBytes: number;
}

export const DEFAULT_UPSTREAM_LIMITS: UpstreamLimits = {
  maxSharedBytes: 4 * 1024 * 1024,
  maxQueuedReads: 64,
  maxCachedAnswers: 32,
  maxCachedBytes: 16 * 1024 * 1024,
};

export interface UpstreamStats {
  /** Requests sent to the controller (or its simulator): reads, commands, held-session re-sends. */
  upstreamRequests: number;
  /** Of which commands. */
  commands: number;
  /** Answers a browser got from another browser's upstream request (joined or kept). */
  sharedAnswers: number;
  /** Reads that had to wait for a slot. */
  queuedReads: number;
  /** Reads answered 503 (queue full, waited too long). */
  refusedReads: number;
  /** Now: reads upstream. */
  readsInFlight: number;
  /** Now: reads waiting for a slot. */
  queueLength: number;
  /** Now: browsers waiting on a shared read in flight. */
  waitingBrowsers: number;
  /** Now: answers kept (not expired). */
  cachedAnswers: number;
}

export interface UpstreamDeps {
  /** The family's declaration for the machine, if any. */
  sharingOf(m: MachineEntry): SharingHints | undefined;
  timeoutMs: number;
  now(): number;
  /** The gateway's agent without keep-alive (commands, families without keep-alive). */
  httpAgent: http.Agent;
  scrub(text: string): string;
  limits?: Partial<UpstreamLimits>;
}

/** One proxied request, as `proxy-http.ts` has it once the gateway's own changes are made. */
export interface UpstreamCall {
  machine: MachineEntry;
  req: IncomingMessage;
  res: ServerResponse;
  method: string;
  /** Canonical controller path (what the family's `shareRead` sees). */
  path: string;
  /** The browser's query, before the gateway's changes (what the family's `shareRead` sees). */
  query: URLSearchParams;
  /** Path and query as they go upstream. */
  pathAndQuery: string;
  /** Headers as they go upstream; a shared read drops the browser's own ones from this object. */
  headers: Record<string, string>;
  isCommand: boolean;
  held: HeldHttp | null;
}

/**
 * Sends the request upstream and answers into `sink` (the browser's response, or a capture shared
 * by several browsers), with `agent` for `http:` controllers.
 */
export type UpstreamRun = (sink: ServerResponse, agent: http.Agent, held: HeldHttp | null) => Promise<void>;

export interface Answer {
  status: number;
  headers: Record<string, string | string[]>;
  body: Buffer;
}

export interface Head {
  status: number;
  headers: Record<string, string | string[]>;
}

export function zeroStats(): UpstreamStats {
  return {
    upstreamRequests: 0,
    commands: 0,
    sharedAnswers: 0,
    queuedReads: 0,
    refusedReads: 0,
    readsInFlight: 0,
    queueLength: 0,
    waitingBrowsers: 0,
    cachedAnswers: 0,
  };
}
