import { z } from 'zod';
import { webhookPayload } from '../alarms';
import { sendJson } from '../http-util';
import type { AuditService, ConfigService, HistoryService, SettingsService } from '../services';
import { retentionSchema, shiftsSchema } from '../settings';
import { DEFAULT_BODY_LIMIT, type ApiRoute } from './route';

/** The server settings (alarm webhook, shifts, history retention): supervisors only. */

/** `PUT /api/settings`: any of the fields, at least one. */
const settingsSchema = z
  .object({
    alarmWebhook: z.string().trim().max(2000).nullable().optional(),
    shifts: shiftsSchema.optional(),
    retention: retentionSchema.optional(),
  })
  .strict()
  .refine((b) => Object.keys(b).length > 0, 'send at least one setting');

const REFUSAL = 'the server settings are for supervisors';

export type SettingsServices = SettingsService &
  HistoryService &
  Pick<AuditService, 'record'> &
  Pick<ConfigService, 'now'>;

export function settingsRoutes({ settings, webhook, history, record, now }: SettingsServices): ApiRoute[] {
  return [
    {
      method: 'GET',
      path: '/api/settings',
      role: 'supervisor',
      refusal: REFUSAL,
      changesState: false,
      audited: false,
      handle(req, res) {
        sendJson(res, 200, {
          ...settings.view(),
          webhook: { ...webhook.stats, waiting: webhook.waiting },
          // The history database's size on disk (bytes), null when it could not be opened.
          historyBytes: history?.store?.sizeBytes() ?? null,
        });
      },
    },
    {
      method: 'PUT',
      path: '/api/settings',
      role: 'supervisor',
      refusal: REFUSAL,
      changesState: true,
      bodyLimit: DEFAULT_BODY_LIMIT,
      audited: true,
      async handle(req, res, call) {
        const { principal: p, address } = call;
        const body = settingsSchema.safeParse(await call.body());
        if (!body.success) {
          const i = body.error.issues[0];
          const where = i?.path.length ? `${i.path.join('.')}: ` : '';
          sendJson(res, 400, {
            error: `send {"alarmWebhook": "https://…" or null, "shifts": [{"name", "start": "HH:MM", "end": "HH:MM"}], "retention": {"jobsDays", "statesDays"}}, any of them (${where}${i?.message ?? 'invalid'})`,
          });
          return;
        }
        const b = body.data;
        const said: string[] = [];
        if (b.alarmWebhook !== undefined) {
          const url = b.alarmWebhook || null;
          const problem = settings.setWebhook(url);
          if (problem) {
            sendJson(res, 400, { error: problem });
            return;
          }
          said.push(
            url
              ? `alarm webhook set to ${settings.view().alarmWebhook.shown ?? ''}`
              : 'alarm webhook removed',
          );
        }
        if (b.shifts || b.retention) {
          const problem = settings.setHistory({ shifts: b.shifts, retention: b.retention });
          if (problem) {
            sendJson(res, 400, { error: problem });
            return;
          }
          if (b.shifts)
            said.push(`shifts: ${b.shifts.map((s) => `${s.name} ${s.start}–${s.end}`).join(', ') || 'none'}`);
          if (b.retention) {
            said.push(
              `history kept: jobs ${b.retention.jobsDays} days, state changes ${b.retention.statesDays} days`,
            );
            history?.prune();
          }
        }
        const view = settings.view();
        record({
          type: 'settings',
          result: 'ok',
          user: p.name,
          onBehalfOf: p.onBehalfOf,
          source: 'gateway',
          address,
          detail: said.join('; ').slice(0, 1000),
        });
        sendJson(res, 200, view);
      },
    },
    {
      method: 'POST',
      path: '/api/settings/test-webhook',
      role: 'supervisor',
      refusal: REFUSAL,
      changesState: true,
      audited: false,
      async handle(req, res, { principal: p }) {
        const t = now();
        const result = await webhook.tryOnce(
          webhookPayload('test', {
            id: 'test',
            machine: 'test',
            machineName: 'Shopdeck',
            family: 'test',
            key: 'test',
            severity: 'info',
            blocking: false,
            text: `a test sent by ${p.name} from the console's settings`,
            since: t,
            clearedAt: null,
            ackBy: null,
            ackAt: null,
          }),
        );
        // Only whether it was delivered: the reason (refused, not HTTP, the receiver's status)
        // would make this a port scanner of the shop network. The server's log says why.
        sendJson(res, 200, result.ok ? { ok: true, result: 'delivered' } : { ok: false, result: 'failed' });
      },
    },
  ];
}
