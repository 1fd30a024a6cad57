import type { StoreApi } from 'zustand/vanilla';
import type { LinkTracker } from '../../fleet/contract';
import { describeError, LinkError } from '../../fleet/errors';
import type { RunToken } from '../../fleet/kernel';
import type { MachineLog } from '../../fleet/log';
import { isNotReady, type TouchcutClient } from './client';
import { authRetryDelay } from '../../fleet/faults';
import { authFromHeld, KEY_AUTH, type TouchcutState } from './state';
import type { HeldLoginWire } from './wire';

/**
 * Who the console is to TouchCut. The gateway holds the machine's TouchCut user login (the JWT,
 * shared by every viewer of the machine) and adds it to every request; without one it adds the
 * machine's API key (if one is configured). This browser never holds a token: it asks the gateway
 * to log in or out (`POST`/`DELETE rest/v1/auth`) and reads who is logged in (`GET rest/v1/auth`,
 * `refreshed`). A 401 means "needs login": the user login expired or was revoked (the gateway has
 * dropped it), or there is none and no accepted key. Nothing is asked of the controller until
 * someone logs in or retries without a login; nothing is retried behind the user's back.
 */

export interface AuthHost {
  client: TouchcutClient;
  store: StoreApi<TouchcutState>;
  tracker: LinkTracker;
  log: MachineLog;
  /** The session's current run: nothing is written once it ended. */
  run: () => RunToken;
  /** Ask the machine again now (status, screen): access changed. */
  resume: () => void;
  now: () => number;
}

/** Why the machine needs a login when TouchCut refused the gateway's API key, and what to do. */
export const KEY_REFUSED =
  'TouchCut refused the console\'s API key (HTTP 401): the console has no accepted API key for this machine. Check its "apiKey" in the machines file and that the key\'s user group has web access, or log in with a TouchCut user. The key is tried again on its own, at most once a minute.';

export class TouchcutAuth {
  /** Bumped by every login and logout here: a login state read before one is stale. */
  private version = 0;
  /**
   * The gateway's API key was refused: tries of it so far, and when the next one is due (null:
   * none). The key is the gateway's, not a user's, so it is tried again on its own, slowly
   * (`authRetryDelay`: a few quick tries, then once a minute). A typed login never is.
   */
  private keyRefusals = 0;
  private keyRetryAt: number | null = null;

  constructor(private readonly h: AuthHost) {}

  /** `POST rest/v1/auth` through the gateway. Errors are thrown with clear words (the login form shows them). */
  async login(credentials: Record<string, string>): Promise<void> {
    const { client, store, log } = this.h;
    const username = credentials.username ?? '';
    const run = this.h.run();
    try {
      const held = await client.login(username, credentials.password ?? '', 'touchcut.login');
      this.version++;
      // The session stopped meanwhile: the gateway holds the login, this session writes nothing.
      if (!run.alive()) return;
      store.setState({ auth: authFromHeld(held, username), notice: null });
      log.info(
        'auth',
        `logged in to TouchCut as ${username} (held by the console's server for every viewer)`,
      );
      this.resume();
    } catch (e) {
      if (run.alive() && isNotReady(e)) store.setState({ notice: describeError(e) });
      log.warn('auth', `TouchCut login as ${username} failed: ${describeError(e)}`);
      throw e;
    }
  }

  /**
   * Ends the machine's user login in the gateway, for every viewer; requests fall back to the API
   * key. A refusal (a viewer may not) is thrown with clear words.
   */
  async logout(): Promise<void> {
    const run = this.h.run();
    const user = this.h.store.getState().auth.user;
    await this.h.client.logout('touchcut.logout');
    this.version++;
    if (!run.alive()) return;
    this.h.store.setState({ auth: KEY_AUTH });
    this.h.log.info('auth', `logged out of TouchCut${user ? ` (${user})` : ''}`);
    this.resume();
  }

  /** Try again without a user login of this browser's (the gateway's API key, or another viewer's login). */
  retryWithoutLogin(): void {
    this.h.store.setState((s) => ({ auth: { ...KEY_AUTH, reason: s.auth.reason } }));
    this.resume();
  }

  /** Marks a read of the login state (`refreshed` drops it if a login or logout came in between). */
  stamp(): number {
    return this.version;
  }

  /**
   * The gateway's login state (read now and then: another viewer may have logged in or out). A
   * login that appeared while this machine needs one: ask the machine again.
   */
  refreshed(held: HeldLoginWire, stamp: number): void {
    if (stamp !== this.version || !this.h.run().alive()) return;
    const { store, tracker } = this.h;
    const now = authFromHeld(held);
    const was = store.getState().auth;
    if (now.mode === 'user') {
      if (was.mode === 'user' && was.user === now.user && was.expiresAt === now.expiresAt) return;
      store.setState({ auth: now });
      if (tracker.state === 'needs-login') this.resume();
    } else if (was.mode === 'user') {
      store.setState({ auth: KEY_AUTH });
    }
  }

  /**
   * A 401 from any request: the machine needs a login. A user login that expired or was revoked
   * waits for someone to log in again (nothing is asked of TouchCut meanwhile, nothing is retried
   * on the user's behalf). Without a user login the credentials are the gateway's API key: it is
   * tried again on its own, slowly (`retryDue`), while the page says the key was refused and what
   * to do.
   */
  failed(e: unknown): void {
    const { store, tracker } = this.h;
    if (!this.h.run().alive()) return;
    const { mode, user } = store.getState().auth;
    let reason: string;
    if (mode === 'user') {
      reason = `The TouchCut login of ${user ?? 'the user'} expired or was revoked: log in again`;
      this.keyRetryAt = null;
    } else {
      reason = KEY_REFUSED;
      this.keyRetryAt = this.h.now() + authRetryDelay(this.keyRefusals++);
    }
    store.setState({ auth: { ...KEY_AUTH, reason } });
    const err = e instanceof LinkError ? new LinkError('http', reason, { status: 401 }) : e;
    tracker.fail(err, { needsLogin: true });
    tracker.patch({ activity: 'unknown', activityLabel: 'Needs login', retryAt: this.keyRetryAt });
  }

  /** The refused API key is due to be tried again (a status read may go while "needs login"). */
  retryDue(): boolean {
    return this.keyRetryAt !== null && this.h.now() >= this.keyRetryAt;
  }

  /** TouchCut accepted a request: the key (or login) works; the retries start over next time. */
  accepted(): void {
    this.keyRefusals = 0;
    this.keyRetryAt = null;
    const { store } = this.h;
    if (store.getState().auth.reason !== null) store.setState((s) => ({ auth: { ...s.auth, reason: null } }));
  }

  private resume(): void {
    if (!this.h.run().alive()) return;
    this.keyRetryAt = null;
    this.h.tracker.patch({ link: 'connecting', problem: null, retryAt: null });
    this.h.resume();
  }
}
