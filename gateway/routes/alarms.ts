import { z } from 'zod';
import { roleAtLeast } from '../../src/fleet/types';
import type { AlarmsService, AuditService, UsersService } from '../services';
import { sendJson } from '../http-util';
import { DEFAULT_BODY_LIMIT, type ApiRoute } from './route';

/**
 * The alarm centre: every signed-in user reads the alarms of their machines; acknowledging one
 * needs an operator, checked after the alarm is found (a viewer's request for an alarm that is not
 * theirs answers 404 as one that does not exist), and a refusal is written to the audit log.
 */

const ackSchema = z.union([
  z.object({ id: z.string().min(1).max(40) }).strict(),
  z.object({ machine: z.string().min(1).max(100), key: z.string().min(1).max(200) }).strict(),
]);
const ALARM_STATES = ['active', 'unacknowledged', 'cleared', 'all'] as const;
const SEVERITIES = ['critical', 'warning', 'info'] as const;

function oneOf<T extends string>(values: readonly T[], v: string | null): T | undefined {
  return values.find((x) => x === v);
}

export type AlarmsServices = AlarmsService &
  Pick<AuditService, 'record'> &
  Pick<UsersService, 'mayUseMachine'>;

export function alarmsRoutes({ alarms, record, mayUseMachine }: AlarmsServices): ApiRoute[] {
  return [
    {
      method: 'GET',
      path: '/api/alarms',
      role: 'viewer',
      changesState: false,
      audited: false,
      handle(req, res, { url, principal }) {
        const p = url.searchParams;
        // A page that already has this version is told so, not sent the list again.
        if (p.get('since') === String(alarms.version)) {
          sendJson(res, 200, { version: alarms.version, unchanged: true });
          return;
        }
        const limit = Number(p.get('limit'));
        const list = alarms.query({
          machines: principal.machines,
          machine: p.get('machine') || undefined,
          family: p.get('family') || undefined,
          severity: oneOf(SEVERITIES, p.get('severity')),
          state: oneOf(ALARM_STATES, p.get('state')),
          limit: Number.isInteger(limit) && limit > 0 ? Math.min(limit, 2000) : 500,
        });
        sendJson(res, 200, { version: alarms.version, alarms: list });
      },
    },
    {
      method: 'POST',
      path: '/api/alarms/ack',
      // Needs an operator, checked after the alarm is found (its refusal audited): see the top.
      role: 'viewer',
      touch: true,
      changesState: true,
      bodyLimit: DEFAULT_BODY_LIMIT,
      audited: true,
      async handle(req, res, call) {
        const { principal, address } = call;
        const pr = principal;
        const body = ackSchema.safeParse(await call.body());
        if (!body.success) {
          sendJson(res, 400, { error: 'send {"id": …} or {"machine": …, "key": …}' });
          return;
        }
        const b = body.data;
        // Only a record the alarm centre has: by id, or the open record of a machine's key. Never
        // in advance (an alarm that has not happened), never an invented key: 404, nothing kept.
        const target = 'id' in b ? alarms.get(b.id) : alarms.open(b.machine, b.key);
        const machineId = target?.machine;
        if (!target || !machineId || !mayUseMachine(pr, machineId)) {
          sendJson(res, 404, { error: 'no such alarm' });
          return;
        }
        if (!roleAtLeast(pr.role, 'operator')) {
          record({
            type: 'refused',
            result: 'refused',
            user: pr.name,
            source: 'gateway',
            machine: machineId,
            label: 'acknowledge alarm',
            role: 'operator',
            address,
            error: 'acknowledging an alarm needs an operator',
          });
          sendJson(res, 403, { error: 'acknowledging an alarm needs an operator', needs: 'operator' });
          return;
        }
        const by = pr.onBehalfOf ? `${pr.name} (on ${pr.onBehalfOf}'s tablet)` : pr.name;
        const out = alarms.acknowledge(target.id, by);
        if (out === 'already' || out === null) {
          sendJson(res, 200, { alarm: target, already: true });
          return;
        }
        const r = out;
        record({
          type: 'alarm-ack',
          result: 'ok',
          user: pr.name,
          onBehalfOf: pr.onBehalfOf,
          source: 'gateway',
          machine: machineId,
          address,
          detail: `acknowledged: ${r.text}`.slice(0, 500),
        });
        sendJson(res, 200, { alarm: r });
      },
    },
  ];
}
