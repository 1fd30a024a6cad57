import type { StoreApi } from 'zustand/vanilla';
import type { LinkTracker } from '../../fleet/contract';
import { describeError, LinkError } from '../../fleet/errors';
import type { RunToken } from '../../fleet/kernel';
import type { MachineLog } from '../../fleet/log';
import { isNotReady, type TouchcutClient } from './client';
import { jwtExpiry, KEY_AUTH, type TouchcutState } from './state';

/**
 * Who the console is to TouchCut. The gateway adds the machine's API key (if one is configured)
 * unless a TouchCut user is logged in here; the user's JWT lives only in the client's memory (the
 * manual: a JWT takes precedence over a key). A 401 means "needs login": with a JWT (it expired)
 * or without one (no key, or the key was revoked). Nothing is asked until someone logs in or
 * retries without a login; nothing is retried behind the user's back.
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
}

export class TouchcutAuth {
  constructor(private readonly h: AuthHost) {}

  /** `POST rest/v1/auth`. Errors are thrown with clear words (the login form shows them). */
  async login(credentials: Record<string, string>): Promise<void> {
    const { client, store, log } = this.h;
    const username = credentials.username ?? '';
    const run = this.h.run();
    try {
      const token = await client.login(username, credentials.password ?? '');
      // The session stopped meanwhile: forget the token rather than write into a stopped session.
      if (!run.alive()) return client.setToken(null);
      store.setState({
        auth: { mode: 'user', user: username, expiresAt: jwtExpiry(token), reason: null },
        notice: null,
      });
      log.info('auth', `logged in to TouchCut as ${username}`);
      this.resume();
    } catch (e) {
      if (run.alive() && isNotReady(e)) store.setState({ notice: describeError(e) });
      log.warn('auth', `TouchCut login as ${username} failed: ${describeError(e)}`);
      throw e;
    }
  }

  /** Forget the user login (the JWT is dropped from memory); requests fall back to the API key. */
  logout(): void {
    const user = this.h.store.getState().auth.user;
    this.h.client.setToken(null);
    this.h.store.setState({ auth: KEY_AUTH });
    if (user) this.h.log.info('auth', `logged out of TouchCut (${user})`);
    this.resume();
  }

  /** Try again without a user login (the gateway's API key, if the machine has one). */
  retryWithoutLogin(): void {
    this.h.client.setToken(null);
    this.h.store.setState((s) => ({ auth: { ...KEY_AUTH, reason: s.auth.reason } }));
    this.resume();
  }

  /** A 401 from any request: the machine needs a login; nothing is asked until the user acts. */
  failed(e: unknown): void {
    const { client, store, tracker } = this.h;
    if (!this.h.run().alive()) return;
    const hadToken = client.loggedIn;
    const user = store.getState().auth.user;
    client.setToken(null);
    const reason = hadToken
      ? `The TouchCut login of ${user ?? 'the user'} expired or was revoked: log in again`
      : 'TouchCut refused the request: the console has no accepted API key for this machine (or the key lacks web access). Log in with a TouchCut user.';
    store.setState({ auth: { ...KEY_AUTH, reason } });
    const err = e instanceof LinkError ? new LinkError('http', reason, { status: 401 }) : e;
    tracker.fail(err, { needsLogin: true });
    tracker.patch({ activity: 'unknown', activityLabel: 'Needs login' });
  }

  private resume(): void {
    if (!this.h.run().alive()) return;
    this.h.tracker.patch({ link: 'connecting', problem: null, retryAt: null });
    this.h.resume();
  }
}
