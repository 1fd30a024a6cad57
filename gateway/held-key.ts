import { createHash, timingSafeEqual } from 'node:crypto';
import type {
  HeldCredentials,
  HeldSessionHooks,
  UpstreamAnswer,
  UpstreamRequest,
} from '../src/fleet/contract';
import type { HeldFailure } from './held-types';
import { unreachableReason } from './log';
import { redact, type MachineEntry } from './machines';
import type { ConfigService, SecretsService } from './services';
import { upstreamRequest, type UpstreamRequestHost } from './upstream-request';

/**
 * The key of a held session (held-session.ts): opened with the configured or typed credentials
 * (one open at a time), renewed or forgotten when the controller says it expired, kept alive
 * while used, closed when unused, on a logout and when the gateway closes. Keys are redacted
 * (`learnSecret`) while in use and a while after.
 */

/** Keys replaced by a renewal stay redacted for a while (late answers): this many of them. */
const RETIRED_KEPT = 4;

type Failure = HeldFailure;
export type Ensured = { ok: true; key: string | null } | Failure;
export type Opened = { ok: true; key: string | null; answer: UpstreamAnswer } | Failure;

/** What the key's lifecycle uses of the gateway. */
export type HeldKeyHost = UpstreamRequestHost &
  Pick<ConfigService, 'log'> &
  Pick<SecretsService, 'learnSecret'>;

function sameSecret(a: string, b: string): boolean {
  const h = (s: string): Buffer => createHash('sha256').update(s, 'utf8').digest();
  return timingSafeEqual(h(a), h(b));
}

export function sameCredentials(a: HeldCredentials, b: HeldCredentials): boolean {
  return sameSecret(a.password, b.password) && (a.username ?? '') === (b.username ?? '');
}

/** The key's lifecycle; `HeldSession` (held-session.ts) adds what browsers' requests do with it. */
export class HeldKey {
  protected key: string | null = null;
  protected open = false;
  /** The controller's connect answer without the key: what a browser's "open" gets. */
  protected answer: UpstreamAnswer | null = null;
  /**
   * What a user typed into the login form (memory only; never logged, never echoed), kept to
   * reopen the session (`expiry` 'reopen' only).
   */
  protected typed: HeldCredentials | undefined;
  protected opening: Promise<Ensured> | null = null;
  /** Bumped whenever a session is installed or ended (an older open in flight is then discarded). */
  protected generation = 0;
  protected retired: string[] = [];
  protected sockets = 0;
  protected inFlight = 0;
  protected lastUsedAt = 0;
  protected lastUpstreamAt = 0;
  protected timer: ReturnType<typeof setInterval> | null = null;
  protected keepAliveInFlight = false;
  protected ended = false;

  constructor(
    protected readonly ctx: HeldKeyHost,
    protected readonly m: MachineEntry,
    protected readonly hooks: HeldSessionHooks,
  ) {}

  protected readonly upstream: UpstreamRequest = (method, pathAndQuery, headers, body) =>
    upstreamRequest(this.ctx, this.m, method, pathAndQuery, headers, { body });

  /** The key is dropped when it expires, never renewed (a user login: TouchCut). */
  protected get forgets(): boolean {
    return this.hooks.expiry === 'forget';
  }

  /** The machines file's credentials for the session (then a typed login is not used). */
  protected configured(): HeldCredentials | undefined {
    if (this.hooks.configured) return this.hooks.configured(this.m.secrets);
    const password = this.m.secrets.password;
    return password === undefined ? undefined : { password };
  }

  // ---------------------------------------------------------------- the session

  /** The open session, opened first when there is none (one open at a time). */
  ensure(): Promise<Ensured> {
    if (this.ended) return Promise.resolve(this.closing());
    if (this.open) return Promise.resolve({ ok: true, key: this.key });
    if (!this.opening) {
      const gen = this.generation;
      const p = this.openWith(this.configured() ?? this.typed)
        .then((r): Ensured | Promise<Ensured> => {
          if (!r.ok) return r;
          if (gen !== this.generation || this.ended) {
            // A login (or the end) came first: this one is not needed.
            if (r.key !== null) void this.closeKey(r.key, this.ended);
            if (this.ended) return this.closing();
            if (this.open) return { ok: true, key: this.key };
            this.opening = null;
            return this.ensure();
          }
          this.install(r.key, r.answer);
          return { ok: true, key: r.key };
        })
        .finally(() => {
          if (this.opening === p) this.opening = null;
        });
      this.opening = p;
    }
    return this.opening;
  }

  /** The controller said `usedKey` expired: a new session (shared with whoever noticed too). */
  renew(usedKey: string | null): Promise<Ensured> {
    this.invalidate(usedKey);
    return this.ensure();
  }

  protected invalidate(usedKey: string | null): void {
    if (this.open && this.key === usedKey) {
      this.open = false;
      this.generation++;
    }
  }

  /**
   * The controller said `usedKey` expired: renewed ('reopen'), or dropped ('forget': the next use
   * finds the session without a key, as the configured credentials open it).
   */
  protected expired(usedKey: string | null): void {
    if (!this.forgets) {
      void this.renew(usedKey);
      return;
    }
    if (usedKey === null || !this.open || this.key !== usedKey) return;
    this.open = false;
    this.generation++;
    this.key = null;
    this.answer = null;
    this.retire(usedKey);
  }

  /** A logout for every viewer: the key is dropped (and closed), typed credentials forgotten. */
  protected logout(): void {
    this.typed = undefined;
    this.stopTimer();
    const key = this.open ? this.key : null;
    this.open = false;
    this.generation++;
    this.key = null;
    this.answer = null;
    if (key !== null) {
      this.retire(key);
      void this.closeKey(key);
    }
  }

  protected closing(): Failure {
    return { ok: false, status: 503, error: 'the gateway is shutting down' };
  }

  protected async openWith(credentials: HeldCredentials | undefined): Promise<Opened> {
    try {
      const r = await this.hooks.open(this.upstream, credentials);
      return r.ok ? r : { ok: false, status: r.answer.status, answer: r.answer };
    } catch (e) {
      return this.unreachable(e, 'opening the controller session');
    }
  }

  /** A request of the gateway's own failed: logged (redacted), and the failure for the browser. */
  protected unreachable(e: unknown, doing: string): Failure {
    const err = e instanceof Error ? e : new Error(String(e));
    const forms = this.ctx.secretsOf.get(this.m.id) ?? [];
    const reason = this.ctx.state.closed ? null : unreachableReason(err, false);
    if (reason) this.ctx.reachability.down(this.m.id, reason, redact(err.message, forms));
    else
      this.ctx.log.error(`${this.m.id}: ${doing}: ${redact(err.message, forms)}`, {
        machine: this.m.id,
      });
    const timedOut = /did not answer within/.test(err.message);
    return {
      ok: false,
      status: timedOut ? 504 : 502,
      error: timedOut ? `${this.m.name} did not answer in time` : `cannot reach ${this.m.name}`,
    };
  }

  protected install(key: string | null, answer: UpstreamAnswer): void {
    if (this.key !== null && this.key !== key) this.retire(this.key);
    if (key !== null) this.ctx.learnSecret(this.m.id, key);
    this.key = key;
    this.answer = answer;
    this.open = true;
    this.generation++;
    this.lastUpstreamAt = Date.now();
    this.startTimer();
  }

  /** A key no longer used stays redacted a while, then is forgotten. */
  protected retire(key: string): void {
    this.retired.push(key);
    while (this.retired.length > RETIRED_KEPT) {
      const old = this.retired.shift();
      if (old !== undefined && old !== this.key) this.ctx.learnSecret(this.m.id, old, false);
    }
  }

  protected async closeKey(key: string, detached = false): Promise<void> {
    if (!this.hooks.close) return;
    const upstream: UpstreamRequest = (method, pathAndQuery, headers, body) =>
      upstreamRequest(this.ctx, this.m, method, pathAndQuery, headers, { detached, body });
    try {
      await this.hooks.close(upstream, key);
    } catch {
      // best effort: the controller forgets it on its own
    }
  }

  /** Unused: end the session; the next use opens a new one. */
  protected release(): void {
    this.stopTimer();
    if (!this.open) return;
    const key = this.key;
    this.open = false;
    this.generation++;
    this.key = null;
    if (key !== null) {
      this.retire(key);
      void this.closeKey(key);
    }
  }

  /** The gateway closes: end the session (best effort: nothing waits for the controller). */
  end(): void {
    this.ended = true;
    this.stopTimer();
    const key = this.open ? this.key : null;
    this.open = false;
    this.generation++;
    if (key !== null) void this.closeKey(key, true);
  }

  // ---------------------------------------------------------------- keep-alive

  protected touch(): void {
    this.lastUsedAt = Date.now();
    this.startTimer();
  }

  protected startTimer(): void {
    const ka = this.hooks.keepAlive;
    if (!ka || this.timer || this.ended || !this.open) return;
    this.timer = setInterval(() => this.tick(), ka.everyMs);
    this.timer.unref();
  }

  protected stopTimer(): void {
    if (this.timer) clearInterval(this.timer);
    this.timer = null;
  }

  protected tick(): void {
    const ka = this.hooks.keepAlive;
    if (!ka || this.ended || !this.open) {
      this.stopTimer();
      return;
    }
    // An open socket keeps the session on the controller's side.
    if (this.sockets > 0) return;
    const now = Date.now();
    if (this.inFlight === 0 && now - this.lastUsedAt > ka.whileUsedWithinMs) {
      this.release();
      return;
    }
    if (this.key === null || this.keepAliveInFlight || now - this.lastUpstreamAt < ka.everyMs / 2) return;
    const key = this.key;
    const headers: Record<string, string> = {};
    this.hooks.apply({ headers, query: new URLSearchParams() }, key);
    this.keepAliveInFlight = true;
    this.lastUpstreamAt = now;
    this.upstream('GET', ka.path, headers)
      .then(
        (r) => {
          if (!this.hooks.isExpired(r.status)) return;
          if (this.forgets) this.expired(key);
          else this.invalidate(key);
        },
        () => undefined,
      )
      .finally(() => {
        this.keepAliveInFlight = false;
      });
  }
}
