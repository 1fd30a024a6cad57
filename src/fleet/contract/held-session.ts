import type { Role } from '../types';

/** A held session: the gateway opens, keeps and renews the controller's session for every viewer. */

export interface GatewaySecrets {
  apiKey?: string;
  password?: string;
}

/** An answer to a request the gateway made itself (held sessions). Header names are lower-case. */
export interface UpstreamAnswer {
  status: number;
  headers: Record<string, string>;
  body: string;
}

/** Sends one request of the gateway's own to the controller (or its simulator). */
export type UpstreamRequest = (
  method: string,
  pathAndQuery: string,
  headers?: Record<string, string>,
  body?: string,
) => Promise<UpstreamAnswer>;

/**
 * What a held session is opened with: the machine's configured password, or what a user typed into
 * the console's login form (a controller with user accounts, TouchCut, also takes a user name).
 */
export interface HeldCredentials {
  password: string;
  username?: string;
}

/** Requests the gateway answers itself from a held session. */
export type HeldIntercept =
  /**
   * The browser's "connect" or login: answered with the session's `answer` (the session is opened
   * first when there is none). `credentials`: what the user typed, when it is in the path or query;
   * `fromBody`: it is in the request body, which the gateway reads (bounded) and hands over with its
   * Content-Type. No credentials at all: the shared session's state as it is.
   */
  | {
      kind: 'open';
      credentials?: HeldCredentials;
      fromBody?: (body: string, contentType: string) => HeldCredentials;
    }
  /**
   * The browser's "disconnect" or logout, answered 204 locally. `end`: the shared session ends too,
   * and typed credentials are forgotten (a user login every viewer shared is logged out); otherwise
   * the shared session stays.
   */
  | { kind: 'close'; end?: boolean }
  /**
   * Sent to the controller by the gateway itself, with its key (and `injectSecrets`), never
   * retried; the answer goes through `exchanged` (a request whose answer carries a new key:
   * TouchCut's password change). The body is read (bounded) and sent as it came.
   */
  | { kind: 'exchange' }
  /** Answered as it is, never forwarded (a method the controller's login resource does not have). */
  | { kind: 'answer'; answer: UpstreamAnswer }
  /**
   * Answered by the family from requests of its own through the held session (`send`: the key
   * applied, never retried; an expired key is renewed for the next one). What a controller hands
   * out once for all its clients (RepRapFirmware's G-code replies) is fetched by the gateway alone
   * and given to each page as its own (the Duet family's `replies.ts`).
   */
  | { kind: 'relay'; run(send: HeldSend): Promise<UpstreamAnswer> };

/** One request of the gateway's own with the held session's key (a `relay` intercept). */
export type HeldSend = (
  method: string,
  path: string,
  query?: URLSearchParams,
  /**
   * `body`: the request body. `onData`: the answer's body is handed over as it comes instead of
   * kept (no size bound; the answer's `body` is then ""); returning false stops reading it.
   */
  opts?: { body?: string; onData?: (chunk: Uint8Array) => boolean },
) => Promise<UpstreamAnswer>;

export type HeldOpen =
  /** `key` null: the controller wants none (no password protection, no user logged in). `answer` never holds the key. */
  | { ok: true; key: string | null; answer: UpstreamAnswer }
  /** Refused (wrong password): the controller's answer, for the browser as it is. */
  | { ok: false; answer: UpstreamAnswer };

/** A family's declaration that the gateway holds the controller's session (Node-safe, pure). */
export interface HeldSessionHooks {
  /** Requests the gateway answers itself instead of forwarding them, or null. */
  intercept(req: {
    method: string;
    path: string;
    query: URLSearchParams;
    /** The browser's role (absent: the gateway's own request, a read). */
    role?: Role;
    /** The request body when the gateway read it to classify it (a G-code body). */
    body?: string;
  }): HeldIntercept | null;
  /**
   * The credentials from the machines file the session is opened with (a typed login is then not
   * used). Default: the configured `password`. TouchCut: none (its `apiKey` is no login).
   */
  configured?(secrets: GatewaySecrets): HeldCredentials | undefined;
  /** Opens a session (`credentials`: the configured ones, else what a user typed, else none). */
  open(upstream: UpstreamRequest, credentials: HeldCredentials | undefined): Promise<HeldOpen>;
  /** Ends a session (unused, the gateway closing): best effort. */
  close?(upstream: UpstreamRequest, key: string): Promise<void>;
  /** Drops any key the browser sent from a forwarded HTTP request, then adds `key` (null: none). */
  apply(req: { headers: Record<string, string>; query: URLSearchParams }, key: string | null): void;
  /** The same for a WebSocket upgrade (the upstream URL's query and the upgrade's headers). */
  applyWs(req: { headers: Record<string, string>; query: URLSearchParams }, key: string | null): void;
  /**
   * The controller's status says the key is unknown or expired (DSF: 403; TouchCut: 401). `req`:
   * the request it answered, when there was one (a keep-alive has none).
   */
  isExpired(status: number, req?: { method: string; path: string }): boolean;
  /**
   * What happens when the key expired. 'reopen' (default): a new session is opened with the
   * configured or typed password (kept in memory for this) and a read is sent once more (DSF).
   * 'forget': the key is dropped and the controller's answer goes to the browser as it is, which
   * then asks for a login again; typed credentials are never kept (a user login that expired is
   * not renewed behind anyone's back: TouchCut).
   */
  expiry?: 'reopen' | 'forget';
  /**
   * The controller's answer to an `exchange` request (`session`: the session's current answer):
   * the key to hold from now on (null: unchanged) and the answer for the browser, which never holds
   * a key. A new key's `answer` also becomes the session's answer (what the next "open" gets).
   */
  exchanged?(
    answer: UpstreamAnswer,
    session: UpstreamAnswer | null,
  ): { key: string | null; answer: UpstreamAnswer };
  /**
   * `GET <path>` with the key every `everyMs` while a browser used the machine within
   * `whileUsedWithinMs` and no upstream socket holds the session open; unused longer, the session
   * is ended and the next request opens a new one.
   */
  keepAlive?: { path: string; everyMs: number; whileUsedWithinMs: number };
}
