import { auditQueryFrom, streamCsv } from '../audit-csv';
import type { AuditService, SecretsService } from '../services';
import { sendJson } from '../http-util';
import type { ApiRoute, GuardedRoute } from './route';

/**
 * The audit log for supervisors: `GET /api/audit` (JSON) and `GET /api/audit.csv` (streamed),
 * limited to the machines of the supervisor's list.
 */

export type AuditServices = Pick<AuditService, 'audit'> & Pick<SecretsService, 'scrub'>;

export function auditRoutes({ audit, scrub }: AuditServices): ApiRoute[] {
  const read: Omit<GuardedRoute, 'path'> = {
    method: 'GET',
    role: 'supervisor',
    refusal: 'the audit log is for supervisors',
    changesState: false,
    audited: false,
    async handle(req, res, { url, principal }) {
      const q = { ...auditQueryFrom(url.searchParams), machines: principal.machines };
      try {
        if (url.pathname.endsWith('.csv')) await streamCsv(audit, q, res);
        else sendJson(res, 200, await audit.query(q));
      } catch (e) {
        if (res.headersSent) res.destroy();
        else
          sendJson(res, 503, {
            error: `the audit log cannot be read: ${scrub(e instanceof Error ? e.message : String(e))}`,
          });
      }
    },
  };
  return [
    { ...read, path: '/api/audit' },
    { ...read, path: '/api/audit.csv' },
  ];
}
