import type { Logger } from './log';

/**
 * Alarms sent on: each alarm event POSTed as JSON to the webhook URL of the server settings, one
 * at a time, in order, retried with backoff when the receiver is down (network error, 5xx, 408,
 * 429); a receiver that refuses (another 4xx) is told once and the event dropped with a log line.
 * The answer's body is never read beyond its status (a receiver is untrusted too), redirects are
 * not followed, and the queue is bounded (the oldest event goes first when it overflows).
 */

export interface WebhookOptions {
  /** The URL now (the settings may change while events wait). */
  url(): string | null;
  log: Logger;
  fetch?: typeof fetch;
  /** Waits between tries (default 2 s, 5 s, 15 s, 60 s, 5 min, 5 min: about 12 minutes in all). */
  backoffMs?: readonly number[];
  timeoutMs?: number;
  maxQueue?: number;
}

export interface WebhookResult {
  ok: boolean;
  status?: number;
  error?: string;
}

const DEFAULT_BACKOFF = [2000, 5000, 15_000, 60_000, 300_000, 300_000];

/** Where a URL points, without its path and query (they often carry the receiver's secret). */
export function shownUrl(url: string): string {
  try {
    const u = new URL(url);
    return `${u.protocol}//${u.host}${u.pathname === '/' && !u.search ? '/' : '/…'}`;
  } catch {
    return '(not a URL)';
  }
}

/** A webhook URL a supervisor may set: http(s), no credentials in it, at most 2000 characters. */
export function webhookUrlProblem(url: string): string | null {
  if (url.length > 2000) return 'the URL is longer than 2000 characters';
  let u: URL;
  try {
    u = new URL(url);
  } catch {
    return 'not a URL';
  }
  if (u.protocol !== 'https:' && u.protocol !== 'http:') return 'the URL must start with https:// or http://';
  if (u.username || u.password) return 'put no user name or password in the URL (use a token in its path)';
  return null;
}

export class Webhook {
  private readonly queue: Array<{ body: string; what: string }> = [];
  private busy = false;
  private timer: ReturnType<typeof setTimeout> | null = null;
  private closed = false;
  /** Delivered, given up, dropped for room (tests, the settings page). */
  readonly stats = { delivered: 0, failed: 0, dropped: 0 };

  constructor(private readonly opts: WebhookOptions) {}

  /** Queues an event for the receiver (nothing when no URL is set). */
  send(what: string, payload: unknown): void {
    if (this.closed || !this.opts.url()) return;
    const max = this.opts.maxQueue ?? 200;
    if (this.queue.length >= max) {
      this.queue.shift();
      this.stats.dropped++;
      this.opts.log.warn('alarm webhook: too many events waiting; the oldest was dropped', { max });
    }
    this.queue.push({ body: JSON.stringify(payload), what });
    this.pump();
  }

  /** One delivery now, not queued, not retried (the settings page's "send a test"). */
  async tryOnce(payload: unknown): Promise<WebhookResult> {
    const url = this.opts.url();
    if (!url) return { ok: false, error: 'no webhook URL is set' };
    return this.post(url, JSON.stringify(payload));
  }

  get waiting(): number {
    return this.queue.length;
  }

  close(): void {
    this.closed = true;
    if (this.timer) clearTimeout(this.timer);
    this.timer = null;
    this.queue.length = 0;
  }

  private pump(): void {
    if (this.busy || this.closed || this.queue.length === 0) return;
    this.busy = true;
    void this.deliver(0);
  }

  private async deliver(attempt: number): Promise<void> {
    const item = this.queue[0];
    const url = this.opts.url();
    if (!item || this.closed) {
      this.busy = false;
      return;
    }
    if (!url) {
      // The URL was removed while events waited: they are not sent anywhere.
      this.queue.length = 0;
      this.busy = false;
      return;
    }
    const r = await this.post(url, item.body);
    if (this.closed) return;
    const retry =
      !r.ok && (r.status === undefined || r.status >= 500 || r.status === 408 || r.status === 429);
    const backoff = this.opts.backoffMs ?? DEFAULT_BACKOFF;
    if (r.ok || !retry || attempt >= backoff.length) {
      this.queue.shift();
      if (r.ok) this.stats.delivered++;
      else {
        this.stats.failed++;
        this.opts.log.error(
          `alarm webhook: ${item.what} not delivered to ${shownUrl(url)} (${r.error ?? `answered ${r.status}`})${retry ? ` after ${attempt + 1} tries` : ''}`,
        );
      }
      this.busy = false;
      this.pump();
      return;
    }
    const wait = backoff[attempt] ?? 300_000;
    this.opts.log.warn(
      `alarm webhook: ${shownUrl(url)} ${r.error ?? `answered ${r.status}`}; trying again in ${Math.round(wait / 1000)} s`,
    );
    this.timer = setTimeout(() => {
      this.timer = null;
      void this.deliver(attempt + 1);
    }, wait);
    this.timer.unref?.();
  }

  private async post(url: string, body: string): Promise<WebhookResult> {
    const f = this.opts.fetch ?? fetch;
    try {
      const res = await f(url, {
        method: 'POST',
        headers: { 'Content-Type': 'application/json', 'User-Agent': 'Shopdeck alarm webhook' },
        body,
        redirect: 'manual',
        signal: AbortSignal.timeout(this.opts.timeoutMs ?? 10_000),
      });
      // The status is all that matters; the body is not read (nor kept waiting).
      await res.body?.cancel().catch(() => undefined);
      return res.status >= 200 && res.status <= 299
        ? { ok: true, status: res.status }
        : { ok: false, status: res.status };
    } catch (e) {
      const err = e instanceof Error ? e : new Error(String(e));
      const cause = (err as Error & { cause?: { code?: unknown } }).cause;
      const code = typeof cause?.code === 'string' ? ` (${cause.code})` : '';
      return {
        ok: false,
        error: err.name === 'TimeoutError' ? 'no answer in time' : `could not connect${code}`,
      };
    }
  }
}
