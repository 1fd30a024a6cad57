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
 * (proxy-http.ts `socketRead`: the user's session now, the family's classification, the role) and
 * sent the same way (held session, secrets, one upstream per machine, shared reads). A request the
 * family classifies as a command is not sent: the answer says `fallback` and the page sends it
 * over HTTP, where a command is proven (X-Shopdeck), given its deadline and audited. Nothing is
 * queued for a socket that is not open: the page reads over HTTP meanwhile.
 *
 * Page → gateway: `{"id": n, "url": "/machines/<id>/<path>?<query>", "headers": {…}}`, or
 * `{"cancel": n}` (the page gave up: its answer is not sent).
 * Gateway → page: `{"id": n, "status": s, "headers": {…}, "body": "<text>"}`, or
 * `{"id": n, "fallback": "<why>"}` for a read that was not sent (read it over HTTP: a command, too
 * many reads at once). A read that was sent is answered, if need be with the gateway's own error
 * (an answer over the size the socket takes, a cut one): never given back to be asked again, as
 * a read may be consumed (RepRapFirmware hands each `rr_reply` out once).
 */

export const READ_SOCKET_PATH = '/api/reads';

export const READ_SOCKET_LIMITS = {
  /** Largest message a page may send (a URL and a few headers). */
  maxMessage: 16 * 1024,
  /** Reads answered at once per socket; more are told to go over HTTP. */
  maxInFlight: 64,
  /** Largest answer sent on the socket; a larger one is the gateway's 502 (no read answers so much). */
  maxAnswer: 8 * 1024 * 1024,
  /** A page that reads its socket slower than this much is waiting is closed (it reads over HTTP). */
  maxBuffered: 16 * 1024 * 1024,
};

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
  ): Promise<SocketReadAnswer>;
}

export function createReadSocket(ctx: GatewayContext, host: ReadSocketHost, limits = READ_SOCKET_LIMITS) {
  const { who, byId, openSockets, scrub } = ctx;
  const sockets = new Set<WebSocket>();
  const wss = new WebSocketServer({
    noServer: true,
    clientTracking: false,
    perMessageDeflate: false,
    maxPayload: limits.maxMessage,
  });

  function upgrade(req: IncomingMessage, socket: Duplex, head: Buffer): void {
    if (refuseUpgrade(ctx, req, socket, { path: READ_SOCKET_PATH })) return;
    const w = who(req, false);
    if (!w.principal)
      return rejectUpgrade(socket, 401, {
        error: w.expired ? 'your session expired: log in again' : 'log in first',
        login: true,
      });
    wss.handleUpgrade(req, socket, head, (client) => serve(client, req));
  }

  function serve(client: WebSocket, req: IncomingMessage): void {
    sockets.add(client);
    openSockets.add(client);
    const inFlight = new Set<number>();
    const cancelled = new Set<number>();
    client.once('close', () => {
      sockets.delete(client);
      openSockets.delete(client);
    });
    client.on('error', () => client.terminate());
    const send = (msg: object): void => {
      if (client.readyState !== client.OPEN) return;
      if (client.bufferedAmount > limits.maxBuffered) {
        client.close(1013, 'the page reads its answers too slowly');
        return;
      }
      client.send(JSON.stringify(msg));
    };
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
        if (inFlight.has(ask.cancel)) cancelled.add(ask.cancel);
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
      inFlight.add(id);
      host
        .read(req, m, target[2] || '/', ask.headers ?? {}, limits.maxAnswer)
        .then(
          (a) => {
            if (cancelled.has(id)) return;
            if ('fallback' in a) {
              send({ id, fallback: a.fallback });
              return;
            }
            const headers: Record<string, string> = {};
            for (const k of PASSED_HEADERS) {
              const v = a.headers[k];
              if (v !== undefined) headers[k] = Array.isArray(v) ? v.join(', ') : v;
            }
            send({ id, status: a.status, headers, body: a.body.toString('utf8') });
            // The user's session ended (logged out, expired, removed): the page learns it from
            // this answer (401) and reads over HTTP from now on.
            if (a.status === 401) client.close(4401, 'log in again');
          },
          (e: unknown) => {
            // It may have reached the controller: an error, never "ask again over HTTP".
            if (!cancelled.has(id))
              send(answerOf(id, 502, { error: e instanceof Error ? e.message : String(e), gateway: true }));
          },
        )
        .finally(() => {
          inFlight.delete(id);
          cancelled.delete(id);
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
