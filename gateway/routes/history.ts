import type { History } from '../history';
import { createHistoryApi, HISTORY_API_PATH, type HistoryApiServices } from '../history/api';
import type { ApiRoute } from './route';

/** `GET /api/history/*` (history/api.ts): any signed-in user; present only with a history. */
export function historyRoutes(ctx: HistoryApiServices, history: History | undefined): ApiRoute[] {
  if (!history) return [];
  const historyApi = createHistoryApi(ctx, history);
  return [
    {
      method: 'GET',
      path: HISTORY_API_PATH,
      example: '/api/history/jobs',
      role: 'viewer',
      changesState: false,
      audited: false,
      notAllowed: 'the history is read-only: GET',
      handle: (req, res, { url, who, principal }) => historyApi(req, res, url, { ...who, principal }),
    },
  ];
}
