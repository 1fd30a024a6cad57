import type { IncomingMessage } from 'node:http';
import type { SharingHints } from '../src/fleet/contract';
import type { MachineEntry } from './machines';
import { MachineLink } from './upstream-link';
import {
  DEFAULT_UPSTREAM_LIMITS,
  zeroStats,
  type UpstreamCall,
  type UpstreamDeps,
  type UpstreamLimits,
  type UpstreamRun,
  type UpstreamStats,
} from './upstream-types';

/**
 * One upstream per machine, HTTP side: whatever the number of viewers, the gateway's requests to
 * one controller are shared and bounded here, as the family declares (`gateway.sharing`,
 * `SharingHints` in src/fleet/contract.ts). A family without `sharing` is forwarded as before:
 * nothing shared, no limit, no keep-alive.
 *
 * - **Coalesced reads.** A GET that is not a command, has no body, and for which the family's
 *   `shareRead(path, query)` gives a window: identical reads (same machine, method, path and query
 *   and headers as they go upstream, i.e. after the gateway's own changes: held session key,
 *   injected secrets) that arrive while one is in flight join it; those that arrive within
 *   `windowMs` after its answer get that answer again. Headers that are the browser's own
 *   business (user agent, `sec-*`, conditional and cache headers) are dropped from a shared read;
 *   every other header goes upstream and is part of the key (`accept`, `range`, `authorization`…),
 *   so two reads the controller could answer differently are never merged. The key is a hash:
 *   no secret is kept in it.
 * - The shared request runs through the proxy's usual path (`forward` / `answerFromSimulator`:
 *   redirect rewriting, safe answer headers, redaction, held-session retry) into a `Capture`,
 *   whose bytes are then given to each waiter. So redaction and header rules are the same for every
 *   answer; `Set-Cookie` (already dropped there) is dropped again on replay.
 * - Only whole answers up to `maxSharedBytes` are kept, and never the gateway's own failures
 *   (`X-Shopdeck-Gateway: error`: unreachable, timed out, refused…); those are given to the
 *   waiters already joined, as they are. A cut answer cuts every waiter's. An answer larger than
 *   `maxSharedBytes` is streamed to the waiters already joined and not kept.
 * - A browser that leaves takes itself out of the waiters; the upstream request is abandoned only
 *   when no waiter is left (as an unshared one is when its browser leaves).
 * - A command clears the machine's kept answers and closes in-flight reads to newcomers: what was
 *   read before a command is not served after it.
 * - Kept answers are per machine, bounded (`maxCachedAnswers`, `maxCachedBytes`), expired ones
 *   dropped on every use.
 *
 * - **Concurrency.** At most `maxConcurrentReads` reads (every non-command request, shared or
 *   not) upstream at once per machine; more wait in a FIFO queue of at most `maxQueuedReads`.
 *   A full queue, or a read that waited longer than `queueTimeoutMs` (default: the gateway's
 *   timeout), is answered 503 `{ error, gateway: true }`. A waiting read whose browser left is
 *   dropped from the queue.
 * - **Commands** never wait in that queue, are never shared, kept or retried (the held session's
 *   rule: a command whose key expired is not re-sent): they go at once, in the order they reach
 *   this point, each on a fresh connection (never on a kept-alive socket the controller may be
 *   closing at that moment: a command is not lost to a stale socket).
 * - **Keep-alive.** Reads to an `http:` controller use one agent per machine, keep-alive as the
 *   family declares. `https:` controllers keep one pinned TLS socket per request
 *   (tls-pin.ts `connectPinned`, in `forward`): no keep-alive there for now.
 * - Simulated machines get the same sharing and limits (they stand in for hardware).
 * - **Counters** per machine (`stats(id)`): upstream requests, shared answers, queued reads, …
 */

export { AnswerTooLarge, captureAnswer } from './upstream-capture';
export {
  DEFAULT_UPSTREAM_LIMITS,
  type UpstreamCall,
  type UpstreamDeps,
  type UpstreamLimits,
  type UpstreamRun,
  type UpstreamStats,
} from './upstream-types';

/** A family's window is capped: a shared answer is never older than this. */
const MAX_WINDOW_MS = 60_000;

function hasBody(req: IncomingMessage): boolean {
  const cl = req.headers['content-length'];
  return (cl !== undefined && cl.trim() !== '0') || req.headers['transfer-encoding'] !== undefined;
}

// ---------------------------------------------------------------- the gateway's

export class UpstreamHttp {
  private readonly links = new Map<string, MachineLink>();
  private readonly limits: UpstreamLimits;

  constructor(private readonly deps: UpstreamDeps) {
    this.limits = { ...DEFAULT_UPSTREAM_LIMITS, ...deps.limits };
  }

  private link(m: MachineEntry): MachineLink {
    let l = this.links.get(m.id);
    if (!l) {
      l = new MachineLink(m, this.deps, this.limits);
      this.links.set(m.id, l);
    }
    return l;
  }

  /**
   * Sends one proxied request upstream as the machine's family declares. Resolves once the
   * request is handed on (a shared read's answer may come later); `run` is not called for a read
   * answered from a kept answer or joined to one in flight.
   */
  async send(r: UpstreamCall, run: UpstreamRun): Promise<void> {
    const sharing = this.deps.sharingOf(r.machine);
    const link = this.link(r.machine);
    if (!sharing) {
      link.stats.upstreamRequests++;
      if (r.isCommand) link.stats.commands++;
      await run(r.res, this.deps.httpAgent, link.counted(r.held, null));
      return;
    }
    if (r.isCommand) {
      await link.command(r, run);
      return;
    }
    const windowMs = r.method === 'GET' && !hasBody(r.req) ? this.windowOf(sharing, r) : null;
    if (windowMs === null) await link.read(r, sharing, run);
    else link.sharedRead(r, sharing, run, windowMs);
  }

  private windowOf(sharing: SharingHints, r: UpstreamCall): number | null {
    let w: number | null;
    try {
      w = sharing.shareRead?.(r.path, new URLSearchParams(r.query)) ?? null;
    } catch {
      return null;
    }
    if (w === null || !Number.isFinite(w) || w < 0) return null;
    return Math.min(w, MAX_WINDOW_MS);
  }

  stats(id: string): UpstreamStats {
    return this.links.get(id)?.snapshot() ?? zeroStats();
  }

  /** Gateway close: queued reads forgotten (their browsers are closed with the server), agents ended. */
  close(): void {
    for (const l of this.links.values()) l.close();
  }
}
