/** What a request's outcome says for the audit log (commands only). */
export type Done = (r: { status?: number; error?: string }) => void;

/**
 * One command on its way to a controller (issue 15): never delivered after the operator was told
 * it was not confirmed. At its deadline (`X-Shopdeck-Deadline`, capped; else the gateway's timeout;
 * none for a streamed upload) or when the browser leaves, everything under way is aborted (a
 * connection or TLS handshake still being made is dropped before a byte is written) and the
 * browser gets 504 "not confirmed" (or a cut answer). `sent`: bytes may have reached the controller.
 */
export class CommandWatch {
  /** Why the command may not be sent any more (null: it may still go). */
  stopped: 'deadline' | 'browser' | null = null;
  sent = false;
  private readonly aborts = new Set<() => void>();
  private timer: ReturnType<typeof setTimeout> | null = null;
  private readonly endsAt: number | null;

  constructor(
    /** The deadline in ms from the request's arrival; null: none. */
    readonly ms: number | null,
    arrivedAt: number,
    private readonly expired: (w: CommandWatch) => void,
  ) {
    this.endsAt = ms === null ? null : arrivedAt + ms;
    if (this.endsAt !== null)
      this.timer = setTimeout(() => this.stop('deadline'), Math.max(0, this.endsAt - Date.now()));
  }

  /** Ms left until the deadline (Infinity: none). */
  remaining(): number {
    return this.endsAt === null ? Number.POSITIVE_INFINITY : Math.max(0, this.endsAt - Date.now());
  }

  /** Runs `abort` when the command stops (at once when it has). Returns: forget it. */
  onAbort(abort: () => void): () => void {
    if (this.stopped) {
      abort();
      return () => undefined;
    }
    this.aborts.add(abort);
    return () => this.aborts.delete(abort);
  }

  stop(why: 'deadline' | 'browser'): void {
    if (this.stopped) return;
    this.stopped = why;
    this.settle();
    if (why === 'deadline') this.expired(this);
    const aborts = [...this.aborts];
    this.aborts.clear();
    for (const a of aborts) a();
  }

  /** The answer was given (or the browser is gone): no deadline any more. */
  settle(): void {
    if (this.timer) clearTimeout(this.timer);
    this.timer = null;
  }
}
