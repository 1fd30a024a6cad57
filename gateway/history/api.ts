import type { IncomingMessage, ServerResponse } from 'node:http';
import type { ConfigService, Principal, Who } from '../services';
import { clientAddress, sendJson } from '../http-util';
import type { History } from './index';

/**
 * `GET /api/history/*` (documented in gateway/README.md): any signed-in user, every answer limited
 * to the machines the user may use. The answers are computed in read workers (answers.ts,
 * read-worker.ts), never on the gateway's thread, within the bounds of reads.ts.
 */

export const HISTORY_API_PATH = /^\/api\/history\/[a-z-]+(\.csv)?$/;
export { MAX_RANGE_DAYS } from './answers';

/** What the history's routes use of the gateway. */
export type HistoryApiServices = Pick<ConfigService, 'config' | 'now'>;

export function createHistoryApi(ctx: HistoryApiServices, history: History) {
  const { config } = ctx;

  /** After the dispatcher's checks (routes/history.ts): a GET of a signed-in user (`w`). */
  return async function historyApi(
    req: IncomingMessage,
    res: ServerResponse,
    url: URL,
    w: Who & { principal: Principal },
  ): Promise<void> {
    req.resume();
    const store = history.store;
    const reads = history.reads;
    if (!store || !reads) {
      sendJson(res, 503, {
        error: `the production history is not available: ${history.problem ?? 'not opened'}`,
      });
      return;
    }
    const csv = url.pathname.endsWith('.csv');
    const route = url.pathname.slice('/api/history/'.length).replace(/\.csv$/, '');
    const pr = w.principal;
    // One asker: the user; in open mode (everyone "anonymous") the address.
    const key = w.mode === 'open' ? `address ${clientAddress(req)}` : `user ${pr.name}`;
    await reads.answer(
      key,
      {
        route,
        csv,
        params: url.searchParams.toString(),
        env: {
          now: ctx.now(),
          machines: config.machines.map((m) => ({ id: m.id, name: m.name, kind: m.kind })),
          allowed: pr.machines,
          settings: history.settings(),
        },
        live: store.liveJobs(),
      },
      res,
    );
  };
}
