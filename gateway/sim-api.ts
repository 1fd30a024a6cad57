import type { IncomingMessage, ServerResponse } from 'node:http';
import type { FaultySimulator } from '../src/fleet/sim';
import {
  FAULT_CONTROLS,
  SIM_RESET,
  simSetSchema,
  type SimControlView,
  type SimPanel,
  type SimSet,
} from '../src/fleet/sim-panel';
import type { AuditService, ConfigService, MachinesService, Principal, UsersService } from './services';
import { clientAddress, decodeSegment, readJson, sendJson } from './http-util';
import type { MachineEntry } from './machines';

/**
 * `/api/sim/<id>`: the Simulator tab of a simulated machine, served by the gateway that runs the
 * simulator (`ctx.simulatorFor`). Simulators live here, not in the page: every tab sees one
 * simulated world, and what changes it goes through the gateway's access control and audit log.
 *
 * - `GET` → `{ machine, kind, controls: [{ group, id, type, label, value?, choices?, unit? }] }`
 *   (src/fleet/sim-panel.ts): the physical-world stand-ins of the family's simulator (`world`),
 *   fault injection with the current values (`faults`) and `simulator.reset`.
 * - `POST { group, id, value? }` sets or runs one control, answers the same as `GET`.
 *
 * Supervisors only (everyone in open mode, which listens on this computer only, unless
 * SHOPDECK_OPEN=1). A machine that is not simulated, or not one of the user's, answers 404.
 * The POST is a state-changing request: the console header (`X-Shopdeck: 1`) is required before
 * this runs (gateway.ts, csrf.ts). Each change is written to the audit log as a command on the
 * machine (`commandId: "sim.<group>.<id>"`); refused changes as refusals.
 */

export const SIM_API_PATH = /^\/api\/sim\/(?<id>[^/]+)$/;

/** The path the audit log names for a request on the simulator of `id` (decoded, cut short). */
export function simAuditPath(id: string): string {
  return `/api/sim/${id.slice(0, 40)}`;
}

/** What the panel shows for this simulator right now. */
export function simPanel(m: MachineEntry, sim: FaultySimulator): SimPanel {
  const f = sim.faults;
  const controls: SimControlView[] = sim
    .controls()
    .map((c) => ({ group: 'world', id: c.id, type: 'action', label: c.label }));
  for (const c of FAULT_CONTROLS) {
    if (c.type === 'toggle') controls.push({ group: 'faults', ...c, value: f[c.id] });
    else if (c.type === 'choice')
      controls.push({ group: 'faults', ...c, choices: [...c.choices], value: f[c.id] });
    else controls.push({ group: 'faults', ...c });
  }
  controls.push({ ...SIM_RESET });
  return { machine: m.id, kind: m.kind, controls };
}

class BadControl extends Error {}

/** What the simulator's route uses of the gateway. */
export type SimServices = Pick<MachinesService, 'byId' | 'simulatorFor' | 'resetSimulator' | 'startDemoJob'> &
  Pick<UsersService, 'mayUseMachine'> &
  Pick<AuditService, 'record'> &
  Pick<ConfigService, 'builtInDemo'>;

/** Sets or runs one control; returns what the audit log says about it. */
function apply(ctx: SimServices, m: MachineEntry, sim: FaultySimulator, set: SimSet): string {
  const v = set.value;
  switch (set.group) {
    case 'world': {
      const c = sim.controls().find((x) => x.id === set.id);
      if (!c) throw new BadControl(`the simulator of ${m.id} has no control "${set.id}"`);
      if (v !== undefined) throw new BadControl(`"${set.id}" is a button: send no value`);
      c.run();
      return c.label;
    }
    case 'faults': {
      const c = FAULT_CONTROLS.find((x) => x.id === set.id);
      if (!c) throw new BadControl(`no fault "${set.id}"`);
      if (c.type === 'action') {
        if (v !== undefined) throw new BadControl(`"${set.id}" is a button: send no value`);
        sim.closeSockets();
        return c.label;
      }
      if (c.type === 'toggle') {
        if (typeof v !== 'boolean') throw new BadControl(`"${set.id}" takes true or false`);
        sim.setFaults({ [c.id]: v });
        return `${c.label}: ${v ? 'on' : 'off'}`;
      }
      if (typeof v !== 'number' || !c.choices.includes(v))
        throw new BadControl(`"${set.id}" takes one of ${c.choices.join(', ')}`);
      sim.setFaults({ [c.id]: v });
      return `${c.label}: ${v} ${c.unit}`;
    }
    case 'simulator': {
      if (set.id !== SIM_RESET.id) throw new BadControl(`no simulator control "${set.id}"`);
      if (v !== undefined) throw new BadControl(`"${set.id}" is a button: send no value`);
      ctx.resetSimulator(m);
      if (ctx.builtInDemo) ctx.startDemoJob(m);
      return SIM_RESET.label;
    }
  }
}

/** `lookNow`: the watch reads the machine at once after a change (gateway.ts), so the alarm centre sees each. */
export function createSimApi(ctx: SimServices, lookNow?: (id: string) => void) {
  const { byId, mayUseMachine, record, simulatorFor } = ctx;

  /**
   * After the dispatcher's checks (routes/machines.ts: GET or POST, a supervisor's session, the
   * refusals of a POST audited): `p` is who asks.
   */
  return async function simApi(
    req: IncomingMessage,
    res: ServerResponse,
    rawId: string,
    p: Principal,
  ): Promise<void> {
    const method = (req.method ?? 'GET').toUpperCase();
    const post = method === 'POST';
    const id = decodeSegment(rawId);
    const address = clientAddress(req);
    const path = simAuditPath(id);
    /** A refused change is written to the audit log (reads are not). */
    const refuse = (error: string): void => {
      req.resume();
      if (!post) return;
      record({
        type: 'refused',
        result: 'refused',
        user: p.name,
        onBehalfOf: p.onBehalfOf,
        source: 'gateway',
        machine: byId.has(id) ? id : undefined,
        method,
        path,
        role: 'supervisor',
        address,
        error,
      });
    };
    const m = byId.get(id);
    if (!m || !m.simulated || !mayUseMachine(p, m.id)) {
      const error = `no simulated machine "${id.slice(0, 40)}"`;
      refuse(error);
      sendJson(res, 404, { error });
      return;
    }
    const sim = simulatorFor(m);
    if (!sim) {
      req.resume();
      sendJson(res, 503, { error: `no simulator for ${m.kind}: the family is not registered` });
      return;
    }
    if (!post) {
      sendJson(res, 200, simPanel(m, sim));
      return;
    }
    const body = simSetSchema.safeParse(await readJson(req));
    if (!body.success) {
      sendJson(res, 400, { error: 'send { "group": "world"|"faults"|"simulator", "id": …, "value"?: … }' });
      return;
    }
    const set = body.data;
    const entry = {
      user: p.name,
      onBehalfOf: p.onBehalfOf,
      source: 'gateway' as const,
      machine: m.id,
      method,
      path,
      commandId: `sim.${set.group}.${set.id}`,
      address,
    };
    let label: string;
    try {
      label = apply(ctx, m, sim, set);
    } catch (e) {
      const message = e instanceof Error ? e.message : String(e);
      if (e instanceof BadControl) {
        sendJson(res, 400, { error: message });
        return;
      }
      record({ ...entry, type: 'command', result: 'error', label: 'Simulator', status: 500, error: message });
      sendJson(res, 500, { error: `the simulator failed: ${message}` });
      return;
    }
    record({ ...entry, type: 'command', result: 'ok', label: `Simulator: ${label}`, status: 200 });
    lookNow?.(m.id);
    const now = simulatorFor(m);
    sendJson(res, 200, now ? simPanel(m, now) : { machine: m.id, kind: m.kind, controls: [] });
  };
}
