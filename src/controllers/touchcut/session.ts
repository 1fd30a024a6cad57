import { describeError, LinkError } from '../../fleet/errors';
import { KernelSession } from '../../fleet/kernel';
import { backoffDelay, HIDDEN_POLL_MS } from '../../fleet/link';
import type { MachineSnapshot } from '../../fleet/types';
import { TouchcutAuth } from './auth';
import { isNotReady, isUnauthorized, REQUEST_TIMEOUT_MS, TouchcutClient } from './client';
import { touchcutCommands } from './commands';
import { asLinkFault, Liveness, quickRetry } from '../../fleet/faults';
import { MonitorFeed, ScreenshotFeed, type FeedHost } from './feeds';
import { identityOf, snapshotPatch, type JobClock } from './normalize';
import { OpenDataFeed, StatsLoader, type ReadHost } from './queries';
import { createTouchcutStore, touchcutUnits } from './state';
import type { Status } from './wire';

export { setTouchcutUnits, touchcutUnits } from './state';
export { jwtExpiry } from './gateway';
export type { TouchcutAuthState, TouchcutState } from './state';
export type { ChangePasswordArgs } from './commands';

export const STATUS_INTERVAL_MS = 1000;
/** "Application not ready" (code 100): TouchCut is starting; look again this soon. */
const NOT_READY_RETRY_MS = 2000;
/**
 * Who the gateway is logged in to TouchCut as (another viewer may log in or out): read this often.
 * The gateway answers it itself; nothing reaches the controller.
 */
export const LOGIN_STATE_INTERVAL_MS = 15_000;
/**
 * Status is read once a second: no good answer for this long is a silent link, shown as down at
 * once (the request itself may wait up to its timeout, client.ts REQUEST_TIMEOUT_MS; a slow answer
 * still counts when it comes). While the page is hidden the poll slows to 10 s or more, and the
 * window grows with it.
 */
export const LIVENESS_MS = 4000;
/**
 * A slow link that still delivers is not silence: the window is at least the poll period and this
 * many times the slowest of the last status answers (SLOW_ANSWERS of them), so answers that take
 * 4 s (2 s latency each way) or 16 s (and TCP and TLS handshakes) keep the link online. It is back
 * to LIVENESS_MS a few answers after the link is fast again.
 */
export const SLOW_ANSWER_FACTOR = 1.5;
const SLOW_ANSWERS = 4;

/**
 * A TouchCut machine at run time, on the session kernel. It polls `status` once a second and
 * `machine-info` (no login) until it is known; views watch the monitor and the screen (feeds.ts)
 * and read statistics, programs and the unloader on demand (queries.ts). Its one command is the
 * user's password change (commands.ts): the REST API is read-only for the machine. Who the
 * console is to TouchCut (the gateway's API key or the user login the gateway holds, "needs
 * login") is auth.ts; the browser never holds a token.
 */
export class TouchcutSession extends KernelSession {
  readonly client = new TouchcutClient(this.machine.id);
  readonly store = createTouchcutStore();
  private readonly host: FeedHost & ReadHost = {
    client: this.client,
    life: this.life,
    queries: this.ctx.queries,
    snapshot: this.ctx.snapshot,
    visibility: this.ctx.visibility,
    now: this.ctx.now,
    units: () => touchcutUnits.getState().units,
    canRequest: () => this.started && this.ctx.snapshot.getState().link !== 'needs-login',
    authFailed: (e) => this.authFailed(e),
  };
  readonly monitor = new MonitorFeed(this.host, (spec) => this.poll(spec));
  readonly screenshot = new ScreenshotFeed(this.host);
  readonly stats = new StatsLoader(this.host);
  readonly programs = new OpenDataFeed(this.host, 'programs');
  readonly unloader = new OpenDataFeed(this.host, 'unloader');
  private readonly declared = touchcutCommands(
    { snapshot: this.ctx.snapshot, touchcut: this.store },
    this.client,
    () => this.run(),
  );
  readonly commands = this.declared.all;
  readonly changePassword = this.declared.changePassword;
  private readonly auth = new TouchcutAuth({
    client: this.client,
    store: this.store,
    tracker: this.tracker,
    log: this.ctx.log,
    run: () => this.run(),
    resume: () => {
      this.status.kick();
      this.screenshot.kick();
    },
    now: this.ctx.now,
  });
  /** When this run started (an outage is measured from the last good data or this). */
  private startedAt = 0;
  /** How long the last status answers took (SLOW_ANSWERS of them): the window grows on a slow link. */
  private answerMs: number[] = [];
  /** When the status read in flight was sent. */
  private statusSentAt = 0;
  /** Status must answer within its window (LIVENESS_MS, more on a slow link). */
  private readonly liveness = new Liveness({
    life: this.life,
    now: this.ctx.now,
    windowMs: () => {
      const slow = STATUS_INTERVAL_MS + Math.max(0, ...this.answerMs) * SLOW_ANSWER_FACTOR;
      const window = Math.min(Math.max(LIVENESS_MS, slow), REQUEST_TIMEOUT_MS + LIVENESS_MS);
      return this.ctx.visibility.hidden() ? HIDDEN_POLL_MS + window : window;
    },
    onSilent: (quiet) => this.silent(quiet),
  });
  private clock: JobClock = { name: null, startedAt: null, lastProgress: null };
  private infoFailures = 0;

  private readonly status = this.poll({
    name: 'status',
    // While "needs login" only when the gateway's refused key is due to be tried again.
    when: () => this.host.canRequest() || (this.started && this.auth.retryDue()),
    read: (signal) => {
      this.statusSentAt = this.ctx.now();
      return this.client.status(this.host.units(), signal);
    },
    apply: (status) => this.applyStatus(status),
    intervalMs: () => STATUS_INTERVAL_MS,
    failed: (e) => this.statusFailed(e),
  });

  /** The gateway's login state; a failure is ignored (asked again later), never touching the link. */
  private readonly loginState = this.poll({
    name: 'login state',
    read: async (signal) => {
      const stamp = this.auth.stamp();
      return { stamp, held: await this.client.loginState(signal) };
    },
    apply: ({ stamp, held }) => this.auth.refreshed(held, stamp),
    intervalMs: () => LOGIN_STATE_INTERVAL_MS,
    failed: () => LOGIN_STATE_INTERVAL_MS,
  });

  /** Cosmetic (the identity line): retried slowly, never touching the link state (status does). */
  private readonly info = this.poll({
    name: 'machine-info',
    when: () => this.store.getState().info === null,
    read: (signal) => this.client.machineInfo(signal),
    apply: (info) => {
      this.store.setState({ info });
      this.tracker.patch({ identity: identityOf(info) });
    },
    intervalMs: () => 60_000,
    failed: (e) => {
      this.ctx.log.add('debug', 'link', `machine-info: ${describeError(e)}`);
      return backoffDelay(this.infoFailures++, { maxMs: 60_000 });
    },
  });

  protected override onStart(): void {
    this.startedAt = this.ctx.now();
    this.answerMs = [];
    this.liveness.start();
    // A units change reads the status again at once, in the new units.
    this.life.onStop(touchcutUnits.subscribe(() => this.status.kick()));
    this.screenshot.kick();
  }

  /** The gateway holds a TouchCut user login for this machine (as last known here). */
  get loggedIn(): boolean {
    return this.store.getState().auth.mode === 'user';
  }

  login(credentials: Record<string, string>): Promise<void> {
    return this.auth.login(credentials);
  }

  /** Logs the machine out of TouchCut in the gateway (for every viewer). */
  logout(): Promise<void> {
    return this.auth.logout();
  }

  retryWithoutLogin(): void {
    this.auth.retryWithoutLogin();
    // Another viewer may have logged the machine in meanwhile.
    this.loginState.kick();
  }

  /** A 401 from any request (auth.ts). */
  authFailed(e: unknown): void {
    this.auth.failed(e);
  }

  private applyStatus(status: Status): void {
    const now = this.ctx.now();
    const before = this.ctx.snapshot.getState();
    const { patch, clock } = snapshotPatch(status, before, this.clock, now);
    const prev = this.store.getState().status;
    this.clock = clock;
    this.answerMs.push(now - this.statusSentAt);
    if (this.answerMs.length > SLOW_ANSWERS) this.answerMs.shift();
    this.liveness.heard();
    this.auth.accepted();
    this.tracker.ok(patch);
    this.store.setState({ status, statusAt: now, notice: null });
    this.logChanges(prev, before, status);
    // Back online with no identity yet: ask now rather than at the end of a long backoff.
    if (before.link !== 'online' && this.store.getState().info === null) this.info.kick();
    // Back from "needs login" by a retry of the key: the screen feed waits for a kick.
    if (before.link === 'needs-login') this.screenshot.kick();
  }

  /** Each change of the machine state and each new message, once, in the machine's log. */
  private logChanges(prev: Status | null, before: MachineSnapshot, s: Status): void {
    if (prev && prev.machineState !== s.machineState)
      this.ctx.log.info('controller', `machine state ${prev.machineState ?? '?'} → ${s.machineState ?? '?'}`);
    const known = new Set(before.alarms.map((a) => a.id));
    for (const a of this.ctx.snapshot.getState().alarms)
      if (!known.has(a.id))
        this.ctx.log.add(a.severity === 'info' ? 'info' : 'warning', 'controller', a.message);
  }

  private statusFailed(e: unknown): number {
    if (isUnauthorized(e)) {
      this.authFailed(e);
      return STATUS_INTERVAL_MS;
    }
    if (isNotReady(e)) {
      // TouchCut is starting. Not an error: say so, look again soon.
      this.store.setState({ notice: describeError(e) });
      this.tracker.patch({ link: 'connecting', activity: 'unknown', activityLabel: 'TouchCut is starting…' });
      return NOT_READY_RETRY_MS;
    }
    this.tracker.fail(asLinkFault(e));
    // Quick retries while the outage is young: back within 5 s of the fault ending.
    return quickRetry(this.ctx, this.tracker, this.startedAt);
  }

  /** Status did not answer within its window: the link is in doubt now, not at the timeout. */
  private silent(quietMs: number): void {
    if (this.tracker.state !== 'online') return;
    this.tracker.fail(
      new LinkError('timeout', `TouchCut has not answered for ${Math.round(quietMs / 1000)} s`),
    );
    // The read in flight is still waiting for its answer: no "next try" time to show.
    this.tracker.patch({ retryAt: null });
  }
}

export const READ_ONLY_NOTE =
  'The TouchCut REST API is read-only: the machine is controlled at the machine, not from this console.';
