import type http from 'node:http';
import type { IncomingMessage, ServerResponse } from 'node:http';
import type { EventEmitter } from 'node:events';
import type { UpstreamAnswer } from '../src/fleet/contract';

/**
 * The types the held session (held-session.ts) shares with the proxies, the shared upstream
 * (upstream-http.ts) and the context: here, so that none of those imports another for them.
 */

/** Handed to the proxy for one forwarded request. */
export interface HeldHttp {
  /**
   * The controller answered `status`. True: the answer is to be dropped, the request is sent
   * again through `resend` once the key is renewed (a read whose key expired; `pathAndQuery` is
   * given when the key changed the query). `dropped`: the upstream request and its answer, to be
   * discarded. A command whose key expired renews the key for the next one and returns false.
   */
  retry(
    status: number,
    resend: (pathAndQuery?: string) => void,
    dropped?: { request: http.ClientRequest; response: IncomingMessage },
    /**
     * Where a refusal goes when no new key could be had: the browser's response by default; a
     * shared read's capture (upstream-http.ts), whose answer every waiting browser gets.
     */
    answerTo?: ServerResponse,
  ): boolean;
}

/** Handed to the WebSocket proxy for one upgrade. */
export interface HeldSocket {
  /** Drops the browser's key from the upstream query and upgrade headers, adds the gateway's. */
  apply(query: URLSearchParams, headers: Record<string, string>): void;
  /** `path?query` for a simulator's socket, with `apply` done. */
  target(path: string, rawQuery: string): string;
  /** The socket that uses the key (browser side for a simulator): the session stays while it is open. */
  track(ws: EventEmitter): void;
}

export interface HeldRefusal {
  status: number;
  body: Record<string, unknown>;
}

/** Why a held session has no key to give: the controller's answer, or the gateway's error. */
export type HeldFailure = { ok: false; status: number; answer?: UpstreamAnswer; error?: string };

/** A forwarded request as the held session sees it (`holdHttp`). */
export interface HeldRequest {
  method: string;
  path: string;
  query: URLSearchParams;
  headers: Record<string, string>;
  isCommand: boolean;
}

/** What the context keeps of a held session (its map by machine id): it can be ended. */
export interface HeldSessionHandle {
  /** The gateway closes or the simulator is reset: end the session (best effort). */
  end(): void;
}
