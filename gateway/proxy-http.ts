import { type IncomingMessage, type ServerResponse } from 'node:http';
import {
  BodyTooLarge,
  clientAddress,
  commandDeadlineMs,
  forwardRequestHeaders,
  readBody,
  secondsWords,
  sendJson,
} from './http-util';
import type { MachineEntry } from './machines';
import { holdHttp } from './held-session';
import { auditTarget, splitTarget, type SplitTarget } from './paths';
import type { GatewayContext, Verdict } from './context';
import { crossSiteProblem } from './csrf';
import type { AccessDecision } from '../src/fleet/access';
import type { Role } from '../src/fleet/types';
import { CommandWatch, type Done } from './command-watch';
import { createForwarder } from './proxy-forward';
import { createSocketlessReads } from './proxy-reads';

export { rewriteLocation } from './proxy-forward';
export type { SocketReadAnswer } from './proxy-reads';

/**
 * `/machines/<id>/*` over HTTP: the request checked (target, body, classification, CSRF, role),
 * a command audited and watched (command-watch.ts), then sent (proxy-forward.ts).
 */

const MAX_CLASSIFY_BODY = 1024 * 1024;
export const READ_METHODS = new Set(['GET', 'HEAD', 'OPTIONS']);

function hasBody(req: IncomingMessage): boolean {
  const cl = req.headers['content-length'];
  return (cl !== undefined && cl.trim() !== '0') || req.headers['transfer-encoding'] !== undefined;
}

export function createHttpProxy(ctx: GatewayContext) {
  const { opts, timeoutMs, record, patternsFor, scrub, who, classify, authorize } = ctx;
  const { forward, answerFromSimulator, gatewayError } = createForwarder(ctx);
  const { watchRead, socketRead } = createSocketlessReads(ctx, (req, res, m, t, headers) =>
    sendUpstream(req, res, m, 'GET', t, headers, null, false, () => undefined),
  );

  // ---------------------------------------------------------------- /machines (HTTP)

  /** Answers a refused request and writes it to the audit log. */
  function refuse(
    req: IncomingMessage,
    res: ServerResponse,
    m: MachineEntry,
    method: string,
    t: SplitTarget,
    decision: AccessDecision,
    v: Extract<Verdict, { ok: false }>,
  ): void {
    const p = who(req, false).principal;
    record({
      type: 'refused',
      result: 'refused',
      machine: m.id,
      method,
      path: scrub(auditTarget(t)),
      label: decision.label,
      address: clientAddress(req),
      source: 'gateway',
      user: p?.name ?? 'nobody',
      onBehalfOf: p?.onBehalfOf,
      role: decision.role,
      error: String(v.body.error),
    });
    req.resume();
    sendJson(res, v.status, v.body);
  }

  async function proxy(
    req: IncomingMessage,
    res: ServerResponse,
    m: MachineEntry,
    rest: string,
  ): Promise<void> {
    const arrivedAt = Date.now();
    const method = (req.method ?? 'GET').toUpperCase();
    const address = clientAddress(req);
    const t = splitTarget(rest);
    if ('error' in t) {
      sendJson(res, 400, { error: t.error });
      return;
    }
    const fam = opts.families[m.kind];
    let body: Buffer | null = null;
    const needsBody = fam?.accessNeedsBody?.(method, t.path) ?? false;
    if (needsBody) {
      // Authorize before reading a body: whatever the body says, the request needs at least
      // this role (a body-classified request is a command: operator unless the family says).
      const least: AccessDecision = {
        role: needsBody === true ? 'operator' : needsBody,
        command: true,
        label: `${method} ${t.path}`,
      };
      const pre = authorize(who(req, false), m, least);
      if (!pre.ok) {
        refuse(req, res, m, method, t, least, pre);
        return;
      }
      const limit = fam?.accessBodyLimit?.(method, t.path) ?? MAX_CLASSIFY_BODY;
      try {
        body = await readBody(req, limit);
      } catch (e) {
        if (e instanceof BodyTooLarge) {
          sendJson(res, 413, { error: `request body larger than ${limit} bytes` });
          return;
        }
        throw e;
      }
    }
    const contentType = body ? req.headers['content-type'] : undefined;
    const decision = classify(m, {
      method,
      path: t.path,
      query: t.query,
      body: body?.toString('utf8'),
      contentType,
    });
    const isCommand = !READ_METHODS.has(method) || decision.command;
    if (isCommand) {
      // A GET the family marks as a command (`/cnc/data?action=stop`) needs the same proof as a
      // POST that the console sent it (non-GET requests were checked in gateway.ts already).
      const crossSite = crossSiteProblem(req, 'command');
      if (crossSite) {
        refuse(req, res, m, method, t, decision, {
          ok: false,
          status: 403,
          body: { error: `refused: ${crossSite}`, crossSite: true },
        });
        return;
      }
    }
    const w = who(req, isCommand);
    const auditPath = scrub(auditTarget(t));
    // The command is what the gateway classified (`decision.id`); the page's own name for it
    // (`X-Shopdeck-Command`) is kept as a label only: a forged one must not name another command.
    const clientCommand =
      typeof req.headers['x-shopdeck-command'] === 'string'
        ? scrub(req.headers['x-shopdeck-command'].slice(0, 100))
        : undefined;
    const base = {
      machine: m.id,
      method,
      path: auditPath,
      commandId: decision.id,
      clientCommand,
      label: decision.label,
      address,
      source: 'gateway' as const,
    };
    const v = authorize(w, m, decision);
    if (!v.ok) {
      if (v.status === 403 || isCommand) {
        record({
          ...base,
          type: 'refused',
          result: 'refused',
          user: w.principal?.name ?? 'nobody',
          onBehalfOf: w.principal?.onBehalfOf,
          role: decision.role,
          error: String(v.body.error),
        });
      }
      req.resume();
      sendJson(res, v.status, v.body);
      return;
    }
    // A command's entry is committed before it is forwarded (a crash after this point leaves it
    // "pending", never missing); one that cannot be audited is not sent.
    const audit = isCommand
      ? ctx.beginCommand({ ...base, user: v.principal.name, onBehalfOf: v.principal.onBehalfOf })
      : null;
    if (isCommand && !audit) {
      req.resume();
      gatewayError(
        res,
        503,
        `${decision.label}: not sent, the audit log cannot be written (see the server log)`,
      );
      return;
    }
    /** A command's outcome, audited once (the first word on it counts: a deadline, a cut answer…). */
    const done: Done = (r) => audit?.done(r);

    let watch: CommandWatch | null = null;
    if (isCommand) {
      // A command whose body streams through (an upload) has no default deadline: its transfer
      // may take long; the idle timeout applies as for reads. Any other command has one.
      const streamed = body === null && hasBody(req);
      const ms = commandDeadlineMs(req.headers['x-shopdeck-deadline'], streamed ? null : timeoutMs);
      const cw = new CommandWatch(ms, arrivedAt, () => {
        const secs = secondsWords(ms ?? 0);
        done({
          status: 504,
          error: `not confirmed within ${secs}: ${
            cw.sent
              ? 'the request was sent; the controller did not answer in time'
              : 'the request was not sent (the controller could not be reached in time)'
          }`,
        });
        if (!res.headersSent && !res.destroyed)
          gatewayError(
            res,
            504,
            `${m.name} did not confirm ${decision.label} within ${secs}: it may or may not have reached the machine`,
            true,
          );
        else res.destroy();
      });
      res.once('close', () => {
        if (res.writableFinished) {
          cw.settle();
          return;
        }
        // The browser stopped waiting (its own deadline, a closed page): not sent after that.
        done({
          error: cw.sent
            ? 'not confirmed: the console stopped waiting (the request was sent)'
            : 'not sent: the console stopped waiting before the controller could be reached',
        });
        cw.stop('browser');
      });
      watch = cw;
    }

    await sendUpstream(
      req,
      res,
      m,
      method,
      t,
      forwardRequestHeaders(req.headers),
      body,
      isCommand,
      done,
      watch,
      v.principal.role,
    );
  }

  /**
   * An authorized request on its way to the controller: the held session's key, the family's
   * secrets, then one upstream per machine (upstream-http.ts). Also the way of the gateway's own
   * reads (the watch, `watchRead`), which have no browser behind them.
   */
  async function sendUpstream(
    req: IncomingMessage,
    res: ServerResponse,
    m: MachineEntry,
    method: string,
    t: SplitTarget,
    headers: Record<string, string>,
    body: Buffer | null,
    isCommand: boolean,
    done: Done,
    watch: CommandWatch | null = null,
    /** The browser's role (a family's held session may answer by it: a Duet job start). */
    role?: Role,
  ): Promise<void> {
    const fam = opts.families[m.kind];
    if (patternsFor(m).length) {
      // A range of an answer could cut a secret into pieces too short to recognise.
      delete headers.range;
      delete headers['if-range'];
    }
    const query = new URLSearchParams(t.query);
    const before = query.toString();
    // Held controller session (held-session.ts): connect/disconnect are answered there, the
    // browser's key is dropped and the gateway's added; `held` re-sends an expired read once.
    const held = await holdHttp(
      ctx,
      m,
      req,
      res,
      { method, path: t.path, query, headers, isCommand, body, role },
      done,
    );
    if (held === 'answered') return;
    // The deadline passed (or the browser left) while the held session was being opened: not sent.
    if (watch?.stopped) return;
    fam?.gateway?.injectSecrets?.({ method, path: t.path, headers, query }, m.secrets);
    const qs = query.toString() === before ? t.rawQuery : query.toString();
    const pathAndQuery = t.path + (qs ? `?${qs}` : '');

    const url = m.url;
    // A serial board (m.serial) is answered by the gateway's bridge, like a simulator.
    if (!m.simulated && !url && !m.serial) {
      sendJson(res, 502, { error: `machine ${m.id} has no url` });
      return;
    }
    // One upstream per machine (upstream-http.ts): identical reads shared, reads limited, commands
    // at once. `sink` is the browser's response, or a capture whose answer several browsers get.
    await ctx.upstream.send(
      { machine: m, req, res, method, path: t.path, query: t.query, pathAndQuery, headers, isCommand, held },
      (sink, agent, h) =>
        m.simulated || !url
          ? answerFromSimulator(req, sink, m, method, pathAndQuery, headers, body, done, h, watch)
          : forward(req, sink, m, url, method, t.path, pathAndQuery, headers, body, done, h, agent, watch),
    );
  }

  return { proxy, watchRead, socketRead };
}
