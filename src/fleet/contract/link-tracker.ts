import { LinkError } from '../errors';
import { backoffDelay } from '../link';
import type { LinkState, MachineSnapshot } from '../types';
import type { SessionContext } from './page';

/**
 * Link bookkeeping shared by sessions: writes link state, problem and retry time into the
 * snapshot, counts failures and computes the backoff.
 */
export class LinkTracker {
  failures = 0;

  constructor(private readonly ctx: SessionContext) {}

  get state(): LinkState {
    return this.ctx.snapshot.getState().link;
  }

  /** Good data arrived. */
  ok(patch: Partial<MachineSnapshot> = {}): void {
    const wasDown = this.state !== 'online';
    this.failures = 0;
    this.ctx.snapshot.setState({
      ...patch,
      link: 'online',
      problem: null,
      retryAt: null,
      updatedAt: this.ctx.now(),
    });
    if (wasDown) this.ctx.log.info('link', 'connected');
  }

  /** Merge vendor data into the snapshot without touching the link state. */
  patch(patch: Partial<MachineSnapshot>): void {
    this.ctx.snapshot.setState(patch);
  }

  /**
   * A request failed. Returns the delay before the next attempt. Network errors and timeouts
   * make the machine `reconnecting`, then `offline` after `offlineAfter` failures; a protocol
   * error shows the path that failed; 401/403 mean `needs-login` when `authFailure` says so.
   */
  fail(e: unknown, opts: { offlineAfter?: number; needsLogin?: boolean } = {}): number {
    this.failures++;
    const delay = backoffDelay(this.failures - 1);
    const err =
      e instanceof LinkError ? e : new LinkError('network', e instanceof Error ? e.message : String(e));
    const offlineAfter = opts.offlineAfter ?? 3;
    let link: LinkState;
    if (opts.needsLogin) link = 'needs-login';
    else if (err.kind === 'protocol') link = 'protocol-error';
    else if (this.failures >= offlineAfter) link = 'offline';
    else link = 'reconnecting';
    const prev = this.ctx.snapshot.getState();
    const offline = link === 'offline' || link === 'reconnecting';
    this.ctx.snapshot.setState({
      link,
      problem: err.toProblem(),
      retryAt: link === 'needs-login' ? null : this.ctx.now() + delay,
      ...(link === 'offline' ? { activity: 'offline', activityLabel: 'Offline' } : {}),
      ...(offline && prev.activity === 'unknown' ? { activityLabel: 'Connecting…' } : {}),
    });
    if (prev.link !== link || prev.problem?.message !== err.message) {
      this.ctx.log.add(
        link === 'protocol-error' ? 'error' : 'warning',
        'link',
        `${linkWords(link)}: ${err.message}`,
      );
    }
    return delay;
  }
}

export function linkWords(link: LinkState): string {
  switch (link) {
    case 'connecting':
      return 'Connecting';
    case 'online':
      return 'Online';
    case 'reconnecting':
      return 'Reconnecting';
    case 'needs-login':
      return 'Needs login';
    case 'protocol-error':
      return 'Protocol error';
    case 'offline':
      return 'Offline';
  }
}
