import type { IncomingMessage } from 'node:http';
import type { Duplex } from 'node:stream';
import { WebSocketServer, type RawData, type WebSocket } from 'ws';
import { z } from 'zod';
import type { GatewayContext } from './context';
import { rejectUpgrade } from './http-util';
import type { MachineEntry } from './machines';
import type { SocketReadAnswer } from './proxy-http';
import { refuseUpgrade } from './proxy-ws';

/**
 * The page's read socket, `WS /api/reads` (issue 16): the polls of every machine a page shows go
 * over one WebSocket instead of one HTTP request each. A browser spends a few milliseconds of its
 * main thread on every `fetch` (measured: 64 small reads a second cost a page 15 % of a core over
 * HTTP, under 2 % as socket messages), and a fleet page of 100 machines makes about 65 a second.
 *
 * Only reads: each message is one GET of `/machines/<id>/…`, checked as that GET over HTTP would be
 * (proxy-reads.ts `socketRead`: the user's session now, the family's classification, the role) and
 * sent the same way (held session, secrets, one upstream per machine, shared reads). A request the
 * family classifies as a command is not sent: the answer says `fallback` and the page sends it
 * over HTTP, where a command is proven (X-Shopdeck), given its deadline and audited. Nothing is
 * queued for a socket that is not open: the page reads over HTTP meanwhile.
 *
 * Page → gateway: `{"id": n, "url": "/machines/<id>/<path>?<query>", "headers": {…}}`, or
 * `{"cancel": n}` (the page gave up: its answer is not sent).
 * Gateway → page: `{"id": n, "status": s, "headers": {…}, "body": "<text>"}`, or
 * `{"id": n, "fallback": "<why>"}` for a read that was not sent (read it over HTTP: a command, too
 * many reads at once) or whose answer is larger than the socket takes (`READ_SOCKET_LIMITS`: it
 * streams over HTTP instead of being held whole here). Any other read that was sent is answered,
 * if need be with the gateway's own error (a cut one): never given back to be asked again, as a
 * read may be consumed (RepRapFirmware hands each `rr_reply` out once; those are a few kB).
 *
 * What the server holds for pages is bounded per socket and per user (sockets per user, bytes
 * being gathered, bytes sent and not yet read, answer size): gateway/README.md.
 */

export const READ_SOCKET_PATH = '/api/reads';

export const READ_SOCKET_LIMITS = {
  /** Largest message a page may send (a URL and a few headers). */
  maxMessage: 16 * 1024,
  /** Reads answered at once per socket; more are told to go over HTTP. */
  maxInFlight: 64,
  /**
   * Largest answer message sent on the socket (bytes of its JSON). A larger answer is not gathered
   * further (its upstream request is dropped) and the page is told to read it over HTTP
   * (`fallback`), where it streams with back-pressure instead of being held whole.
   */
  maxAnswer: 1024 * 1024,
  /**
   * Bytes of answers being gathered from controllers for one socket at once; a read whose answer
   * would go beyond is told to read over HTTP (`fallback`).
   */
  maxGathering: 2 * 1024 * 1024,
  /** Bytes sent to a page and not yet taken by it; one answer more is refused by closing it (1013). */
  maxBuffered: 2 * 1024 * 1024,
  /** Read sockets one user has open at once; one more is refused (429: that page reads over HTTP). */
  maxSocketsPerUser: 8,
  /** Bytes held for one user's sockets together (gathered and unsent), checked as for one socket. */
  maxHeldPerUser: 8 * 1024 * 1024,
};

export type ReadSocketLimits = typeof READ_SOCKET_LIMITS;

/** What the read sockets hold now, and the most they held at once (tests, benchmarks). */
export interface ReadSocketHeld {
  /** Bytes of answers being gathered from controllers. */
  gathering: number;
  /** Bytes sent to pages and not yet taken by them. */
  unsent: number;
  /** The most `gathering + unsent` has been since the gateway started. */
  peak: number;
}

/** The answer headers a page gets on the socket (what the console's clients read). */
const PASSED_HEADERS = ['content-type', 'x-shopdeck-gateway', 'retry-after'];

const HEADER_NAME = /^[!#$%&'*+.^_`|~0-9A-Za-z-]+$/;
const HEADER_VALUE = /^[\t\x20-\x7e\x80-\xff]*$/;

const Ask = z.union([
  z
    .object({
      id: z
        .number()
        .int()
        .positive()
        .max(2 ** 31),
      url: z.string().min(1).max(4096),
      // Header names and values as HTTP allows them (no line breaks to smuggle a second header).
      headers: z
        .record(z.string().max(100).regex(HEADER_NAME), z.string().max(4096).regex(HEADER_VALUE))
        .optional(),
    })
    .strict(),
  z
    .object({
      cancel: z
        .number()
        .int()
        .positive()
        .max(2 ** 31),
    })
    .strict(),
]);

export interface ReadSocketHost {
  read(
    from: IncomingMessage,
    m: MachineEntry,
    rest: string,
    headers: Record<string, string>,
    cap: number,
    /** Aborted when the page gives the read up or its socket closes. */
    signal?: AbortSignal,
    /** Each chunk of the answer before it is kept: false refuses it as too large. */
    take?: (bytes: number) => boolean,
  ): Promise<SocketReadAnswer>;
}

/** One user's read sockets (key: the account, the operator behind a supervisor's unlock). */
interface UserSockets {
  sockets: Set<WebSocket>;
  /** Bytes being gathered for them. */
  gathering: number;
}

/** One read in flight on a socket. */
interface InFlight {
  abort: AbortController;
  /** Bytes of its answer gathered so far (counted in the socket's and user's `gathering`). */
  taken: number;
  cancelled: boolean;
}

export function createReadSocket(
  ctx: GatewayContext,
  host: ReadSocketHost,
  given: Partial<ReadSocketLimits> = {},
) {
  const limits: ReadSocketLimits = { ...READ_SOCKET_LIMITS, ...given };
  const { who, byId, openSockets, scrub } = ctx;
  const sockets = new Set<WebSocket>();
  const users = new Map<string, UserSockets>();
  let gatheringAll = 0;
  let peak = 0;
  const wss = new WebSocketServer({
    noServer: true,
    clientTracking: false,
    perMessageDeflate: false,
    maxPayload: limits.maxMessage,
  });

  /** Whose sockets these are: one account's, whatever unlock it holds (open mode: per address). */
  function userKey(w: ReturnType<typeof who>): string {
    const p = w.principal;
    if (!p) return '';
    return w.mode === 'open' ? `open ${p.name}` : `user ${p.onBehalfOf ?? p.name}`;
  }

  function unsentOf(set: Iterable<WebSocket>): number {
    let n = 0;
    for (const s of set) n += s.bufferedAmount;
    return n;
  }

  function held(): ReadSocketHeld {
    const unsent = unsentOf(sockets);
    peak = Math.max(peak, gatheringAll + unsent);
    return { gathering: gatheringAll, unsent, peak };
  }

  function upgrade(req: IncomingMessage, socket: Duplex, head: Buffer): void {
    if (refuseUpgrade(ctx, req, socket, { path: READ_SOCKET_PATH })) return;
    const w = who(req, false);
    if (!w.principal)
      return rejectUpgrade(socket, 401, {
        error: w.expired ? 'your session expired: log in again' : 'log in first',
        login: true,
      });
    const key = userKey(w);
    if ((users.get(key)?.sockets.size ?? 0) >= limits.maxSocketsPerUser)
      return rejectUpgrade(socket, 429, {
        error: `${limits.maxSocketsPerUser} read sockets are open for this user already: this page reads over HTTP`,
      });
    wss.handleUpgrade(req, socket, head, (client) => serve(client, req, key));
  }

  function serve(client: WebSocket, req: IncomingMessage, key: string): void {
    let user = users.get(key);
    if (!user) {
      user = { sockets: new Set(), gathering: 0 };
      users.set(key, user);
    }
    if (user.sockets.size >= limits.maxSocketsPerUser) {
      // Two upgrades at once passed the check above: the later one is closed here.
      client.close(1013, 'too many read sockets for this user');
      return;
    }
    const mine = user;
    sockets.add(client);
    openSockets.add(client);
    mine.sockets.add(client);
    const inFlight = new Map<number, InFlight>();
    let gathering = 0;
    client.once('close', () => {
      sockets.delete(client);
      openSockets.delete(client);
      mine.sockets.delete(client);
      if (mine.sockets.size === 0 && users.get(key) === mine) users.delete(key);
      // Nobody will read these answers: their upstream requests are dropped, their slots freed.
      for (const f of inFlight.values()) f.abort.abort();
    });
    client.on('error', () => client.terminate());
    /** Counts `bytes` more of one read's answer, if the socket's and the user's bounds allow. */
    const take = (f: InFlight, bytes: number): boolean => {
      if (f.cancelled) return false;
      if (f.taken + bytes > limits.maxAnswer || gathering + bytes > limits.maxGathering) return false;
      if (mine.gathering + unsentOf(mine.sockets) + bytes > limits.maxHeldPerUser) return false;
      f.taken += bytes;
      gathering += bytes;
      mine.gathering += bytes;
      gatheringAll += bytes;
      held();
      return true;
    };
    const giveBack = (f: InFlight): void => {
      gathering -= f.taken;
      mine.gathering -= f.taken;
      gatheringAll -= f.taken;
      f.taken = 0;
    };
    const sendText = (text: string): void => {
      if (client.readyState !== client.OPEN) return;
      const bytes = Buffer.byteLength(text);
      if (
        client.bufferedAmount + bytes > limits.maxBuffered ||
        mine.gathering + unsentOf(mine.sockets) + bytes > limits.maxHeldPerUser
      ) {
        client.close(1013, 'the page reads its answers too slowly');
        return;
      }
      client.send(text);
      held();
    };
    const send = (msg: object): void => sendText(JSON.stringify(msg));
    const tooLarge = (id: number): object => ({
      id,
      fallback: `the answer is larger than the read socket takes (${limits.maxAnswer} bytes): read it over HTTP`,
    });
    client.on('message', (data: RawData, isBinary: boolean) => {
      if (isBinary) {
        client.close(1003, 'text messages only');
        return;
      }
      let ask: z.infer<typeof Ask>;
      try {
        ask = Ask.parse(JSON.parse(rawText(data)));
      } catch {
        client.close(1008, 'not a read request');
        return;
      }
      if ('cancel' in ask) {
        const f = inFlight.get(ask.cancel);
        if (f && !f.cancelled) {
          // Not answered; its upstream request dropped as a browser's that leaves.
          f.cancelled = true;
          f.abort.abort();
        }
        return;
      }
      const { id } = ask;
      if (inFlight.has(id)) {
        client.close(1008, 'a request id still in use');
        return;
      }
      if (inFlight.size >= limits.maxInFlight) {
        send({ id, fallback: 'too many reads at once' });
        return;
      }
      const target = /^\/machines\/([^/?#]+)(.*)$/.exec(ask.url);
      if (!target) {
        send(answerOf(id, 400, { error: 'only /machines/<id>/… is read here' }));
        return;
      }
      let machineId = '';
      try {
        machineId = decodeURIComponent(target[1] ?? '');
      } catch {
        machineId = '';
      }
      const m = byId.get(machineId);
      if (!m) {
        send(
          answerOf(id, 404, { error: `no machine "${scrub(machineId.slice(0, 60))}" in the machines file` }),
        );
        return;
      }
      const f: InFlight = { abort: new AbortController(), taken: 0, cancelled: false };
      inFlight.set(id, f);
      let ended: Promise<SocketReadAnswer>;
      try {
        ended = host.read(
          req,
          m,
          target[2] || '/',
          ask.headers ?? {},
          limits.maxAnswer,
          f.abort.signal,
          (n) => take(f, n),
        );
      } catch (e) {
        ended = Promise.reject(e instanceof Error ? e : new Error(String(e)));
      }
      ended
        .then(
          (a) => {
            // What it gathered is now this answer, counted as unsent once it is sent.
            giveBack(f);
            if (f.cancelled) return;
            if ('fallback' in a) {
              send(a.tooLarge ? tooLarge(id) : { id, fallback: a.fallback });
              return;
            }
            const headers: Record<string, string> = {};
            for (const k of PASSED_HEADERS) {
              const v = a.headers[k];
              if (v !== undefined) headers[k] = Array.isArray(v) ? v.join(', ') : v;
            }
            const text = JSON.stringify({ id, status: a.status, headers, body: a.body.toString('utf8') });
            // Escaped as JSON, an answer may grow beyond what the socket takes: read over HTTP.
            if (Buffer.byteLength(text) > limits.maxAnswer) send(tooLarge(id));
            else sendText(text);
            // The user's session ended (logged out, expired, removed): the page learns it from
            // this answer (401) and reads over HTTP from now on. A controller's own 401 (a
            // refused API key, its session expired) is that machine's answer only: the socket
            // stays open for every other machine's reads.
            if (a.status === 401 && !who(req, false).principal) client.close(4401, 'log in again');
          },
          (e: unknown) => {
            giveBack(f);
            // It may have reached the controller: an error, never "ask again over HTTP".
            if (!f.cancelled)
              send(
                answerOf(id, 502, {
                  error: scrub(e instanceof Error ? e.message : String(e)),
                  gateway: true,
                }),
              );
          },
        )
        .finally(() => {
          // Every way a read ends (answered, failed, cancelled, its socket closed) gives back
          // what it held and its id.
          giveBack(f);
          if (inFlight.get(id) === f) inFlight.delete(id);
        });
    });
  }

  return {
    upgrade,
    /** Shutdown: every read socket told the console is going away (pages read over HTTP). */
    goingAway(reason: string): number {
      let told = 0;
      for (const s of [...sockets]) {
        s.close(1001, reason);
        told++;
      }
      return told;
    },
    /** Open read sockets (tests, benchmarks). */
    get open(): number {
      return sockets.size;
    },
    /** Bytes the read sockets hold now, and the most they held (tests, benchmarks). */
    held,
  };
}

function answerOf(id: number, status: number, body: unknown): object {
  return {
    id,
    status,
    headers: { 'content-type': 'application/json; charset=utf-8', 'x-shopdeck-gateway': 'error' },
    body: JSON.stringify(body),
  };
}

function rawText(data: RawData): string {
  if (Buffer.isBuffer(data)) return data.toString('utf8');
  if (Array.isArray(data)) return Buffer.concat(data).toString('utf8');
  return Buffer.from(data).toString('utf8');
}
