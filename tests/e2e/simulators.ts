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

/** A fresh simulated world for each test: every simulator restarted, without faults. */
export async function resetSimulators(
  request: APIRequestContext,
  machines: readonly string[] = DEMO_MACHINES,
): Promise<void> {
  for (const m of machines) await simulator(request, m, 'simulator', 'reset');
}
