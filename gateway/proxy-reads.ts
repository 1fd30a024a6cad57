import { IncomingMessage, type ServerResponse } from 'node:http';
import { Socket } from 'node:net';
import type { GatewayContext } from './context';
import { clientAddress, forwardRequestHeaders, sendJson } from './http-util';
import type { MachineEntry } from './machines';
import { auditTarget, splitTarget, type SplitTarget } from './paths';
import { AnswerTooLarge, captureAnswer } from './upstream-http';

/** The watch reads status answers: a few kB; a model (Duet) some tens. */
const WATCH_READ_MAX = 2 * 1024 * 1024;

/** A read sent the browsers' way (proxy-http.ts `sendUpstream`: a GET, no body, not a command). */
export type SendRead = (
  req: IncomingMessage,
  res: ServerResponse,
  m: MachineEntry,
  t: SplitTarget,
  headers: Record<string, string>,
) => Promise<void>;

/** Reads without a browser's HTTP request: the gateway's watch, and a page's read socket. */
export function createSocketlessReads(ctx: GatewayContext, sendRead: SendRead) {
  const { classify, who, authorize, record, scrub } = ctx;

  /**
   * The gateway's own read of a machine (its watch, watch.ts): no browser behind it, so no user
   * and no role check, hence only what the family classifies as a read. It takes the browsers'
   * way (held session, secrets, sharing: within a window it costs the controller nothing).
   */
  async function watchRead(
    m: MachineEntry,
    pathAndQuery: string,
  ): Promise<{ status: number; body: string; gateway: boolean }> {
    const t = splitTarget(pathAndQuery);
    if ('error' in t) throw new Error(t.error);
    const decision = classify(m, { method: 'GET', path: t.path, query: t.query });
    if (decision.command) throw new Error(`${t.path} is a command: the watch only reads`);
    const req = new IncomingMessage(new Socket());
    req.method = 'GET';
    req.url = pathAndQuery;
    req.push(null);
    const { res, answer } = captureAnswer(WATCH_READ_MAX);
    try {
      await sendRead(req, res, m, t, {});
    } catch (e) {
      // Closed, so whatever counts it (the held session's reads under way) lets go of it.
      res.destroy();
      answer.catch(() => undefined);
      throw e;
    }
    const a = await answer;
    // `X-Shopdeck-Gateway` is the gateway's own (a controller's is never passed on): unreachable.
    const gateway = a.headers['x-shopdeck-gateway'] !== undefined;
    return { status: a.status, body: a.body.toString('utf8'), gateway };
  }

  /**
   * A read sent over a page's read socket (read-socket.ts) instead of an HTTP GET: the same checks
   * and the same way upstream as that GET, the answer captured whole (at most `cap` bytes). Never a
   * command: one the family classifies as such is not sent (`fallback`: the page uses HTTP).
   */
  async function socketRead(
    from: IncomingMessage,
    m: MachineEntry,
    rest: string,
    browserHeaders: Record<string, string>,
    cap: number,
    /** The page gave up or its socket closed: the read is abandoned (its upstream slot freed). */
    signal?: AbortSignal,
    /** Each chunk of the answer as it is gathered: false refuses it (the answer is too large). */
    take?: (bytes: number) => boolean,
  ): Promise<SocketReadAnswer> {
    const { res, answer } = captureAnswer(cap, take);
    const abandon = (): void => {
      if (!res.writableFinished) res.destroy();
    };
    if (signal?.aborted) abandon();
    signal?.addEventListener('abort', abandon, { once: true });
    const settled = async (): Promise<SocketReadAnswer> => {
      try {
        const a = await answer;
        return { status: a.status, headers: a.headers, body: a.body };
      } catch (e) {
        if (e instanceof AnswerTooLarge) return { fallback: e.message, tooLarge: true };
        // Cut. The controller was asked already: the page is told it failed, never sent to ask
        // again (a read may be consumed, as RepRapFirmware's rr_reply).
        const why = e instanceof Error ? e.message : String(e);
        return {
          status: 502,
          headers: { 'content-type': 'application/json; charset=utf-8', 'x-shopdeck-gateway': 'error' },
          body: Buffer.from(JSON.stringify({ error: `${m.name}: ${why}`, gateway: true })),
        };
      } finally {
        signal?.removeEventListener('abort', abandon);
      }
    };
    const t = splitTarget(rest);
    if ('error' in t) {
      sendJson(res, 400, { error: t.error });
      return settled();
    }
    const decision = classify(m, { method: 'GET', path: t.path, query: t.query });
    if (decision.command) {
      signal?.removeEventListener('abort', abandon);
      return { fallback: 'a command goes over HTTP' };
    }
    const w = who(from, false);
    const v = authorize(w, m, decision);
    if (!v.ok) {
      if (v.status === 403)
        record({
          type: 'refused',
          result: 'refused',
          machine: m.id,
          method: 'GET',
          path: scrub(auditTarget(t)),
          label: decision.label,
          address: clientAddress(from),
          source: 'gateway',
          user: w.principal?.name ?? 'nobody',
          onBehalfOf: w.principal?.onBehalfOf,
          role: decision.role,
          error: String(v.body.error),
        });
      sendJson(res, v.status, v.body);
      return settled();
    }
    const req = new IncomingMessage(new Socket());
    req.method = 'GET';
    req.url = rest;
    req.push(null);
    try {
      await sendRead(req, res, m, t, forwardRequestHeaders(browserHeaders));
    } catch (e) {
      // The proxy threw before it could answer (its read slot is already released): the page
      // gets the gateway's error, as a browser over HTTP would (gateway.ts).
      if (!res.headersSent && !res.destroyed)
        sendJson(res, 500, { error: scrub(e instanceof Error ? e.message : String(e)), gateway: true });
      else res.destroy();
    }
    return settled();
  }

  return { watchRead, socketRead };
}

/** What a read sent over a page's read socket comes to (`socketRead`). */
export type SocketReadAnswer =
  | { status: number; headers: Record<string, string | string[]>; body: Buffer }
  /**
   * Not sent: the page sends it over HTTP (a command); or `tooLarge`: larger than the socket takes
   * (the page reads it over HTTP, where it streams).
   */
  | { fallback: string; tooLarge?: boolean };
