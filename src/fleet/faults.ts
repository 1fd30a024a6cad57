import type { LinkTracker, SessionContext } from './contract';
import { LinkError } from './errors';
import type { Lifecycle } from './kernel';
import type { Deadline } from './kernel/scheduler';
import { backoffDelay, type BackoffOptions } from './link';

/**
 * Link faults against verdicts (issue 15), shared by every family. A request that failed — no
 * answer, a timeout, the console server's own failure (it could not reach the controller), a 5xx,
 * a cut answer — says nothing about the controller: it is a link problem, retried quickly, never
 * "unsupported model", "needs login" or "incompatible version". Only a complete answer of the
 * controller itself can give a verdict, and a verdict is re-checked on every reconnect.
 */

/** Retries while an outage is young are at most this far apart: back within 5 s of the fault ending. */
export const QUICK_RETRY_MAX_MS = 2500;
/** An outage older than this is retried on the DESIGN's backoff (up to 30 s). */
export const QUICK_RETRY_FOR_MS = 5 * 60_000;
export const SLOW_RETRY_MAX_MS = 30_000;

/**
 * The console server's own failure body, `{"error": …, "gateway": true}`, with or without its
 * `X-Shopdeck-Gateway` header (HttpClient reads the header; this reads the body): never the controller's.
 */
export function gatewayBodyError(status: number, body: unknown): LinkError | null {
  if (status < 400 || typeof body !== 'object' || body === null) return null;
  const b = body as { error?: unknown; gateway?: unknown };
  if (b.gateway !== true) return null;
  const words = typeof b.error === 'string' ? b.error : `the console server answered HTTP ${status}`;
  return new LinkError(status >= 500 ? 'network' : 'http', words.slice(0, 300), {
    status,
    fromGateway: true,
  });
}

/** The console server answered for the controller (it could not reach it, or refused the request). */
export function fromGateway(e: unknown): boolean {
  return e instanceof LinkError && e.fromGateway;
}

/** A cut (truncated) or unreadable answer: the body broke off, or what came is not JSON. */
export function isCutAnswer(e: unknown): boolean {
  if (!(e instanceof LinkError)) return e instanceof TypeError;
  return e.kind === 'protocol' && /not JSON/i.test(e.message);
}

/** Nothing (or nothing whole) came from the controller itself: a link problem, never a verdict. */
export function isLinkFault(e: unknown): boolean {
  if (!(e instanceof LinkError)) return true;
  if (fromGateway(e)) return true;
  switch (e.kind) {
    case 'network':
    case 'timeout':
    case 'offline':
      return true;
    case 'http':
    case 'vendor':
      return e.status !== null && e.status >= 500;
    case 'protocol':
      return isCutAnswer(e);
    case 'aborted':
      return false;
  }
}

/** The error as the link shows it: a cut answer is a failed request, not a protocol error. */
export function asLinkFault(e: unknown): unknown {
  if (e instanceof LinkError && !isCutAnswer(e)) return e;
  if (e instanceof LinkError) return new LinkError('network', `The answer was cut off (${e.message})`);
  return new LinkError('network', `The answer was cut off (${e instanceof Error ? e.message : String(e)})`);
}

/**
 * After `tracker.fail`: the delay before the next try, quick (≤ 2.5 s) while the outage is young so
 * the machine is back within 5 s of the fault ending, the DESIGN's backoff after that. Written as
 * the snapshot's `retryAt`.
 */
export function quickRetry(ctx: SessionContext, tracker: LinkTracker, startedAt: number): number {
  const s = ctx.snapshot.getState();
  const now = ctx.now();
  const downFor = now - Math.max(s.updatedAt ?? 0, startedAt);
  const maxMs = downFor < QUICK_RETRY_FOR_MS ? QUICK_RETRY_MAX_MS : SLOW_RETRY_MAX_MS;
  const delay = backoffDelay(Math.max(0, tracker.failures - 1), { maxMs });
  if (s.link !== 'needs-login') tracker.patch({ retryAt: now + delay });
  return delay;
}

/**
 * A liveness rule: no good answer for `windowMs` is silence, reported once (`onSilent`) until the
 * next good answer. The end of the window is a deadline of the run's (`Lifecycle.deadline`, one
 * implementation with the socket heartbeat's): an answer moves it on without a new timer, a window
 * that shrank (the slow-link rule) sets it nearer; silence is seen at the window's end exactly.
 * About one wake-up per answer, not one every quarter (xTool: tenth) of a second. Ends with the run.
 */
export class Liveness {
  private lastHeard = 0;
  private reported = false;
  private readonly end: Deadline<unknown>;

  constructor(
    private readonly o: {
      life: Lifecycle;
      now: () => number;
      windowMs: () => number;
      onSilent: (quietMs: number) => void;
    },
  ) {
    this.end = o.life.deadline({
      now: o.now,
      due: () => (this.reported ? null : this.lastHeard + this.o.windowMs()),
      fire: () => {
        this.reported = true;
        this.o.onSilent(this.o.now() - this.lastHeard);
      },
    });
  }

  /** On start: the clock starts now. */
  start(): void {
    this.lastHeard = this.o.now();
    this.reported = false;
    this.end.update(true);
  }

  /** A good answer came. */
  heard(): void {
    this.lastHeard = this.o.now();
    this.reported = false;
    this.end.update();
  }
}

/**
 * Credentials that are the gateway's (an API key, the machine's configured password) and were
 * refused are tried again on their own: every 2.5 s for the first few tries (a key that was
 * refused for a few seconds, a password changed and changed back, is back within 5 s of being
 * right again), then backing off to at most once a minute, so a wrong key neither hammers the
 * controller nor locks an account. A login typed by a user is never retried on their behalf.
 */
export const AUTH_QUICK_TRIES = 4;
export const AUTH_RETRY_BASE_MS = 2500;
export const AUTH_RETRY_MAX_MS = 60_000;

/**
 * The socket's reconnect backoff: quick (≤ 2.5 s) while the outage is young, the DESIGN's after
 * that. A getter, read by the socket at each reconnect.
 */
export function quickBackoff(ctx: SessionContext, startedAt: () => number): BackoffOptions {
  return {
    get maxMs(): number {
      const s = ctx.snapshot.getState();
      const downFor = ctx.now() - Math.max(s.updatedAt ?? 0, startedAt());
      return downFor < QUICK_RETRY_FOR_MS ? QUICK_RETRY_MAX_MS : SLOW_RETRY_MAX_MS;
    },
  };
}

/** The delay before try `attempt` (from 0) of refused credentials that are the gateway's. */
export function authRetryDelay(attempt: number): number {
  if (attempt < AUTH_QUICK_TRIES) return backoffDelay(0, { baseMs: AUTH_RETRY_BASE_MS, jitter: 0.1 });
  return backoffDelay(attempt - AUTH_QUICK_TRIES + 1, {
    baseMs: AUTH_RETRY_BASE_MS,
    maxMs: AUTH_RETRY_MAX_MS,
    jitter: 0.2,
  });
}
