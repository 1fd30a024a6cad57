import type { MachineApi } from '../types';
import type { GatewaySecrets, HeldSessionHooks } from './held-session';
import type { SharedStreamDecl } from './streams';
import type { WatchDecl } from './watch';

/** What a family tells the gateway (Node-safe, pure): secrets, sharing, held sessions, sockets. */

export interface GatewayHints {
  /** WebSocket port on the controller's host when the machine has no `wsUrl` (xTool: 8081). */
  defaultWsPort?: number;
  /**
   * Answers the console shows as images (thumbnails, screenshots, help pictures): only these keep a
   * raster image type; every other image answer is served as a download (gateway/answer-headers.ts).
   */
  imageAnswer?: (path: string) => boolean;
  /**
   * Add secrets to a forwarded request. `headers` and `query` are mutable copies; never put a
   * secret anywhere it could be echoed back to the browser.
   */
  injectSecrets?: (
    req: { method: string; path: string; headers: Record<string, string>; query: URLSearchParams },
    secrets: GatewaySecrets,
  ) => void;
  /**
   * The gateway holds this controller's session (gateway/held-session.ts): it opens it, keeps the
   * key, renews and keeps it alive, and adds it on the way out; the browser never sees the key.
   */
  session?: HeldSessionHooks;
  /**
   * How the gateway shares this controller among every viewer (gateway/upstream-http.ts,
   * gateway/streams.ts, gateway/watch.ts): one upstream per machine whatever the number of tabs.
   */
  sharing?: SharingHints;
  /**
   * Controller sockets bridged one to one (each browser socket its own upstream socket, frames
   * passed both ways), for a socket that cannot be shared. None of the five families has one:
   * every socket of theirs is a shared stream (`sharing.streams`). A WebSocket path that is
   * neither is refused (404) before anything reaches the controller. At most `maxPerMachine`
   * such upstream sockets are open for one machine (more: 503).
   */
  bridgedSockets?: { matches(path: string): boolean; maxPerMachine: number };
  /**
   * The session hooks and sharing hints of ONE machine (the gateway asks once per machine and
   * keeps them), for a family whose controllers speak more than one API: which one is learned
   * when the session is opened (Duet: DSF or standalone `rr_*`, the held session's probe) or told
   * by the machines file's `api`. Without it, `session` and `sharing` serve every machine.
   */
  forMachine?(m: { id: string; api?: MachineApi }): { session?: HeldSessionHooks; sharing?: SharingHints };
}

/**
 * A family's declaration of how its controller is shared (`<kind>/sharing.ts`, Node-safe, pure).
 * The mechanism is the gateway's, once; the family only says what is safe for its controller.
 */
export interface SharingHints {
  /**
   * Identical reads (GET, same path and query, not a command) that may be answered from one
   * upstream request: the window in ms within which an answer is given again (the family's poll
   * period for that path), or null: never shared. Commands are never shared, cached or retried.
   */
  shareRead?(path: string, query: URLSearchParams): number | null;
  /** Keep TCP connections to the controller open between requests (its server allows it). */
  keepAlive: boolean;
  /**
   * At most this many reads upstream at once for one machine; more wait in a queue (bounded).
   * Commands never wait behind reads: they go at once, in the order they arrived.
   */
  maxConcurrentReads: number;
  /** The controller's WebSockets that are shared: one upstream socket per machine and path. */
  streams?: SharedStreamDecl[];
  /** The slow watch the gateway keeps on the machine with no viewer (state and alarms). */
  watch?: WatchDecl;
}
