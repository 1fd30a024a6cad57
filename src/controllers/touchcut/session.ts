import { createStore, type StoreApi } from 'zustand/vanilla';
import type { CommandDecl } from '../../fleet/commands';
import { LinkTracker, type MachineSession, type SessionContext } from '../../fleet/contract';
import { describeError, LinkError } from '../../fleet/errors';
import { backoffDelay, Poller } from '../../fleet/link';
import type { MachineInfo } from '../../fleet/types';
import { isNotReady, isUnauthorized, TouchcutClient } from './client';
import { MonitorFeed, OpenDataFeed, ScreenshotFeed, StatsLoader, type FeedHost } from './feeds';
import { identityOf, snapshotPatch, type JobClock } from './normalize';
import { UNITS_CHOICES, type MachineInfoWire, type Status, type UnitsChoice } from './wire';

/**
 * A TouchCut machine at run time: polls `status` once a second (slower while hidden, via Poller),
 * reads `machine-info` once (no login), and offers on-demand feeds (monitor, screenshot, stats,
 * programs, unloader) to the views.
 *
 * Authentication: the gateway adds the machine's API key (if one is configured) unless a TouchCut
 * user is logged in here; the user's JWT lives only in this session's memory. A 401 means
 * "needs login": with a JWT (it expired) or without one (no key, or the key was revoked). Polling
 * stops until someone logs in or retries without a login; nothing is retried behind the user's back.
 */

export const STATUS_INTERVAL_MS = 1000;

export interface TouchcutAuthState {
  /** 'key': requests rely on the gateway's API key; 'user': a TouchCut user JWT is in memory. */
  mode: 'key' | 'user';
  user: string | null;
  /** JWT expiry (ms since epoch) if the token says so (display only). */
  expiresAt: number | null;
  /** Why a login is needed, in words. */
  reason: string | null;
}

export interface TouchcutState {
  info: MachineInfoWire | null;
  status: Status | null;
  statusAt: number | null;
  auth: TouchcutAuthState;
  /** A passing condition shown as a notice, not an error (TouchCut "application not ready"). */
  notice: string | null;
}

/** Units are a per-user choice of the console user (kept in this browser; not a secret). */
const UNITS_KEY = 'shopdeck.touchcut.units';

function loadUnits(): UnitsChoice {
  try {
    const v = globalThis.localStorage?.getItem(UNITS_KEY);
    return UNITS_CHOICES.includes(v as UnitsChoice) ? (v as UnitsChoice) : 'default';
  } catch {
    return 'default';
  }
}

export const touchcutUnits: StoreApi<{ units: UnitsChoice }> = createStore(() => ({ units: loadUnits() }));

export function setTouchcutUnits(units: UnitsChoice): void {
  touchcutUnits.setState({ units });
  try {
    globalThis.localStorage?.setItem(UNITS_KEY, units);
  } catch {
    /* storage unavailable: the choice lasts for this page */
  }
}

/** Reads `exp` of a JWT for display. The token is untrusted: any failure gives null. */
export function jwtExpiry(token: string): number | null {
  try {
    const part = token.split('.')[1];
    if (!part) return null;
    const json = atob(part.replace(/-/g, '+').replace(/_/g, '/') + '==='.slice((part.length + 3) % 4));
    const exp = (JSON.parse(json) as { exp?: unknown }).exp;
    return typeof exp === 'number' && Number.isFinite(exp) ? exp * 1000 : null;
  } catch {
    return null;
  }
}

export interface ChangePasswordArgs {
  oldPassword: string;
  newPassword: string;
  confirmPassword: string;
}

export class TouchcutSession implements MachineSession {
  readonly machine: MachineInfo;
  readonly client: TouchcutClient;
  readonly store: StoreApi<TouchcutState>;
  readonly monitor: MonitorFeed;
  readonly screenshot: ScreenshotFeed;
  readonly stats: StatsLoader;
  readonly programs: OpenDataFeed;
  readonly unloader: OpenDataFeed;
  readonly commands: Readonly<Record<string, CommandDecl<never>>>;
  readonly changePassword: CommandDecl<ChangePasswordArgs>;
  private readonly tracker: LinkTracker;
  private readonly poller: Poller;
  private infoTimer: ReturnType<typeof setTimeout> | null = null;
  private infoAttempts = 0;
  private retryDelay = STATUS_INTERVAL_MS;
  private stopped = true;
  private clock: JobClock = { name: null, startedAt: null, lastProgress: null };
  private lastMachineState: string | undefined;
  private unsubUnits: (() => void) | null = null;

  constructor(readonly ctx: SessionContext) {
    this.machine = ctx.machine;
    this.client = new TouchcutClient(ctx.machine.id);
    this.tracker = new LinkTracker(ctx);
    this.store = createStore<TouchcutState>(() => ({
      info: null,
      status: null,
      statusAt: null,
      auth: { mode: 'key', user: null, expiresAt: null, reason: null },
      notice: null,
    }));
    const host: FeedHost = {
      client: this.client,
      visibility: ctx.visibility,
      now: ctx.now,
      units: () => touchcutUnits.getState().units,
      canRequest: () => !this.stopped && this.ctx.snapshot.getState().link !== 'needs-login',
      authFailed: (e) => this.authFailed(e),
    };
    this.monitor = new MonitorFeed(host);
    this.screenshot = new ScreenshotFeed(host);
    this.stats = new StatsLoader(host);
    this.programs = new OpenDataFeed(host, 'programs');
    this.unloader = new OpenDataFeed(host, 'unloader');
    this.poller = new Poller({
      run: () => this.pollStatus(),
      intervalMs: () => STATUS_INTERVAL_MS,
      visibility: ctx.visibility,
      onError: (e) => this.statusFailed(e),
      retryDelayMs: () => this.retryDelay,
    });
    this.changePassword = {
      id: 'touchcut.changePassword',
      label: 'Change TouchCut password',
      hazard: 'adjust',
      role: 'operator',
      confirm: false,
      available: () =>
        this.client.loggedIn ? true : 'Needs a TouchCut user login (an API key cannot change a password)',
      perform: async (args, c) => {
        const token = await this.client.changePassword(args, c.commandId);
        this.store.setState((s) => ({ auth: { ...s.auth, expiresAt: jwtExpiry(token) } }));
        return 'password changed; new login token in use';
      },
    };
    this.commands = { [this.changePassword.id]: this.changePassword as CommandDecl<never> };
  }

  start(): void {
    if (!this.stopped) return;
    this.stopped = false;
    this.fetchInfo();
    this.poller.start(0);
    this.unsubUnits = touchcutUnits.subscribe(() => this.poller.kick());
  }

  stop(): void {
    this.stopped = true;
    this.poller.stop();
    if (this.infoTimer) clearTimeout(this.infoTimer);
    this.infoTimer = null;
    this.monitor.stop();
    this.screenshot.stop();
    this.programs.stop();
    this.unloader.stop();
    this.unsubUnits?.();
    this.unsubUnits = null;
  }

  get loggedIn(): boolean {
    return this.client.loggedIn;
  }

  /** `POST rest/v1/auth`. Errors are thrown with clear words (the login form shows them). */
  async login(credentials: Record<string, string>): Promise<void> {
    const username = credentials.username ?? '';
    const password = credentials.password ?? '';
    try {
      const token = await this.client.login(username, password);
      this.store.setState({
        auth: { mode: 'user', user: username, expiresAt: jwtExpiry(token), reason: null },
        notice: null,
      });
      this.ctx.log.info('auth', `logged in to TouchCut as ${username}`);
      this.resume();
    } catch (e) {
      if (isNotReady(e)) this.store.setState({ notice: describeError(e) });
      this.ctx.log.warn('auth', `TouchCut login as ${username} failed: ${describeError(e)}`);
      throw e;
    }
  }

  /** Forget the user login (the JWT is dropped from memory); requests fall back to the API key. */
  logout(): void {
    const user = this.store.getState().auth.user;
    this.client.setToken(null);
    this.store.setState({ auth: { mode: 'key', user: null, expiresAt: null, reason: null } });
    if (user) this.ctx.log.info('auth', `logged out of TouchCut (${user})`);
    this.resume();
  }

  /** Try again without a user login (the gateway's API key, if the machine has one). */
  retryWithoutLogin(): void {
    this.client.setToken(null);
    this.store.setState((s) => ({ auth: { ...s.auth, mode: 'key', user: null, expiresAt: null } }));
    this.resume();
  }

  private resume(): void {
    if (this.stopped) return;
    this.tracker.patch({ link: 'connecting', problem: null, retryAt: null });
    this.poller.stop();
    this.poller.start(0);
    this.screenshot.kick();
  }

  /** A 401 from any request: the machine needs a login. Polling stops until the user acts. */
  authFailed(e: unknown): void {
    if (this.stopped) return;
    const hadToken = this.client.loggedIn;
    const user = this.store.getState().auth.user;
    this.client.setToken(null);
    const reason = hadToken
      ? `The TouchCut login of ${user ?? 'the user'} expired or was revoked: log in again`
      : 'TouchCut refused the request: the console has no accepted API key for this machine (or the key lacks web access). Log in with a TouchCut user.';
    this.store.setState({ auth: { mode: 'key', user: null, expiresAt: null, reason } });
    const err = e instanceof LinkError ? new LinkError('http', reason, { status: 401 }) : e;
    this.tracker.fail(err, { needsLogin: true });
    this.ctx.snapshot.setState({ activity: 'unknown', activityLabel: 'Needs login' });
    this.poller.stop();
  }

  private fetchInfo(): void {
    if (this.stopped) return;
    this.client
      .machineInfo()
      .then((info) => {
        this.store.setState({ info });
        this.tracker.patch({ identity: identityOf(info) });
      })
      .catch((e: unknown) => {
        if (this.stopped) return;
        // machine-info is cosmetic: retry slowly without touching the link state (status does).
        this.ctx.log.add('debug', 'link', `machine-info: ${describeError(e)}`);
        this.infoTimer = setTimeout(
          () => this.fetchInfo(),
          backoffDelay(this.infoAttempts++, { maxMs: 60_000 }),
        );
      });
  }

  private async pollStatus(): Promise<void> {
    if (this.stopped) return;
    const status = await this.client.status(touchcutUnits.getState().units);
    if (this.stopped) return;
    const now = this.ctx.now();
    const { patch, clock } = snapshotPatch(status, this.ctx.snapshot.getState(), this.clock, now);
    const prevAlarms = this.ctx.snapshot.getState().alarms;
    this.clock = clock;
    this.tracker.ok(patch);
    this.store.setState({ status, statusAt: now, notice: null });
    this.logChanges(
      status,
      prevAlarms.map((a) => a.id),
    );
    if (this.store.getState().info === null && !this.infoTimer) this.fetchInfo();
  }

  private logChanges(s: Status, prevAlarmIds: string[]): void {
    if (s.machineState !== this.lastMachineState) {
      if (this.lastMachineState !== undefined) {
        this.ctx.log.info(
          'controller',
          `machine state ${this.lastMachineState ?? '?'} → ${s.machineState ?? '?'}`,
        );
      }
      this.lastMachineState = s.machineState;
    }
    for (const a of this.ctx.snapshot.getState().alarms) {
      if (!prevAlarmIds.includes(a.id))
        this.ctx.log.add(a.severity === 'info' ? 'info' : 'warning', 'controller', a.message);
    }
  }

  private statusFailed(e: unknown): void {
    if (isUnauthorized(e)) {
      this.authFailed(e);
      return;
    }
    if (isNotReady(e)) {
      // "Application not ready" (code 100): TouchCut is starting. Not an error: say so, look again soon.
      this.store.setState({ notice: describeError(e) });
      this.tracker.patch({ link: 'connecting', activity: 'unknown', activityLabel: 'TouchCut is starting…' });
      this.retryDelay = 2000;
      return;
    }
    this.retryDelay = this.tracker.fail(e);
  }
}

export const READ_ONLY_NOTE =
  'The TouchCut REST API is read-only: the machine is controlled at the machine, not from this console.';
