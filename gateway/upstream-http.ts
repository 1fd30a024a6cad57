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
 * one controller are shared and bounded here as the family declares (`gateway.sharing`,
 * `SharingHints` in src/fleet/contract.ts): coalesced reads, a read limit with its queue (503 when
 * full or too long), commands at once on a fresh connection and never shared, kept or retried,
 * keep-alive, counters. A family without `sharing` is forwarded as before. Simulated machines get
 * the same. The rules in full: gateway/README.md, "One upstream per machine (HTTP)".
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
