import type { AuditService, ConfigService, LinksService, MachinesService, UsersService } from '../services';
import { sendJson } from '../http-util';
import { listPins, pinInfo } from '../tls-pin';
import type { ApiRoute } from './route';

/** The controllers' pinned TLS certificates (tls-pin.ts): supervisors only. */

export type TlsServices = Pick<ConfigService, 'config'> &
  Pick<MachinesService, 'byId'> &
  Pick<LinksService, 'pins' | 'tlsPools'> &
  Pick<AuditService, 'record'> &
  Pick<UsersService, 'mayUseMachine'>;

export function tlsRoutes({ config, byId, pins, tlsPools, record, mayUseMachine }: TlsServices): ApiRoute[] {
  return [
    {
      method: 'GET',
      path: '/api/tls',
      role: 'supervisor',
      refusal: 'the controllers’ certificates are for supervisors',
      changesState: false,
      audited: false,
      handle(req, res, { principal: p }) {
        try {
          sendJson(res, 200, {
            machines: listPins(
              config.machines.filter((m) => mayUseMachine(p, m.id)),
              pins,
            ),
          });
        } catch (e) {
          sendJson(res, 500, { error: e instanceof Error ? e.message : String(e) });
        }
      },
    },
    {
      method: 'DELETE',
      path: /^\/api\/tls\/(?<id>[a-z0-9-]{1,40})$/,
      example: '/api/tls/p1',
      role: 'supervisor',
      refusal: 'accepting a new certificate is for supervisors',
      changesState: true,
      audited: true,
      handle(req, res, { principal: p, params, address }) {
        const m = byId.get(params.id ?? '');
        const view = m && mayUseMachine(p, m.id) ? pinInfo(m, pins) : null;
        if (!m || !view) {
          sendJson(res, 404, { error: 'no machine reached over TLS by that id' });
          return;
        }
        if (!view.canForget) {
          sendJson(res, 409, {
            error:
              view.mode === 'configured'
                ? 'its fingerprint is in the machines file (tlsFingerprint): change it there'
                : 'no certificate is pinned for it yet',
          });
          return;
        }
        const gone = pins.forget(m.id);
        // Connections checked against the forgotten pin are not used again (tls-pool.ts).
        tlsPools.drop(m.id);
        record({
          type: 'tls-forget',
          result: 'ok',
          user: p.name,
          onBehalfOf: p.onBehalfOf,
          source: 'gateway',
          machine: m.id,
          address,
          detail: `forgot the pinned certificate ${gone?.fingerprint ?? ''}: the next connection trusts what it is shown`,
        });
        sendJson(res, 200, { forgotten: gone });
      },
    },
  ];
}
