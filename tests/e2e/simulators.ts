import type { APIRequestContext } from '@playwright/test';

/**
 * The demo machines of `tests/e2e/demo-machines.json` are answered by simulators that run in the
 * console's server for the whole run (every tab, every test and both projects see the same
 * simulated world), driven through `POST /api/sim/<id>` as the Simulator tab does
 * (gateway/sim-api.ts). Open mode: anyone on this computer may drive them.
 */

export const DEMO_MACHINES = ['demo-xtool', 'demo-touchcut', 'demo-duet', 'demo-prunt', 'demo-g2core'];

/** Sets or runs one control of a simulated machine (`value` for a fault toggle or choice). */
export async function simulator(
  request: APIRequestContext,
  machine: string,
  group: 'world' | 'faults' | 'simulator',
  id: string,
  value?: boolean | number,
): Promise<void> {
  const r = await request.post(`/api/sim/${machine}`, {
    // The console's own header (gateway/csrf.ts): every state-changing request carries it.
    headers: { 'X-Shopdeck': '1' },
    data: value === undefined ? { group, id } : { group, id, value },
  });
  if (!r.ok())
    throw new Error(`POST /api/sim/${machine} ${group}.${id}: HTTP ${r.status()} ${await r.text()}`);
}

/**
 * A fresh simulated world for each test: every simulator restarted, without faults, and every
 * alarm an earlier test left in the alarm centre acknowledged (a critical one would otherwise
 * stay on every page, as it should on a shop floor, until someone acknowledges it).
 */
export async function resetSimulators(
  request: APIRequestContext,
  machines: readonly string[] = DEMO_MACHINES,
): Promise<void> {
  for (const m of machines) await simulator(request, m, 'simulator', 'reset');
  await acknowledgeAllAlarms(request);
}

/** Acknowledges every unacknowledged alarm of the alarm centre (open mode: anyone may). */
export async function acknowledgeAllAlarms(request: APIRequestContext): Promise<void> {
  const r = await request.get('/api/alarms?state=unacknowledged&limit=2000');
  if (!r.ok()) throw new Error(`GET /api/alarms: HTTP ${r.status()} ${await r.text()}`);
  const { alarms } = (await r.json()) as { alarms: Array<{ id: string }> };
  for (const a of alarms) {
    const ack = await request.post('/api/alarms/ack', { headers: { 'X-Shopdeck': '1' }, data: { id: a.id } });
    if (!ack.ok()) throw new Error(`POST /api/alarms/ack ${a.id}: HTTP ${ack.status()} ${await ack.text()}`);
  }
}
