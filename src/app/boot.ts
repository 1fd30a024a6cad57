import { z } from 'zod';
import { controllers } from '../controllers';
import { authStore } from '../fleet/auth';
import { createRuntime, fleetStore, getRuntime, registerRuntime, allRuntimes } from '../fleet/fleet';
import { MACHINE_KINDS, type MachineInfo } from '../fleet/types';
import { CONSOLE_HEADERS } from '../fleet/origin';
import { fetchSession, trackActivity } from './auth/api';

const MachinesAnswer = z.object({
  machines: z.array(
    z.object({
      id: z.string(),
      name: z.string(),
      kind: z.enum(MACHINE_KINDS),
      simulated: z.boolean(),
    }),
  ),
});

export async function loadSession(): Promise<void> {
  try {
    await fetchSession();
  } catch {
    // A gateway without access control: behave as open mode, and say so in the banner.
    authStore.setState({ mode: 'open', user: null });
  }
  trackActivity();
}

/**
 * Loads the fleet, creates and starts one session per machine. Simulated machines are answered by
 * the gateway's simulators like hardware (one simulated world for every tab): nothing is
 * simulated in the page.
 */
export async function boot(): Promise<void> {
  await loadSession();
  let machines: MachineInfo[];
  try {
    const r = await fetch('/api/machines', { credentials: 'same-origin', headers: CONSOLE_HEADERS });
    if (r.status === 401) {
      fleetStore.setState({ status: 'ready', machines: [], error: null });
      return;
    }
    if (!r.ok) throw new Error(`the gateway answered HTTP ${r.status}`);
    const parsed = MachinesAnswer.safeParse(await r.json());
    if (!parsed.success)
      throw new Error(`the machine list is malformed: ${parsed.error.issues[0]?.message ?? ''}`);
    machines = parsed.data.machines;
  } catch (e) {
    fleetStore.setState({
      status: 'error',
      error: `Cannot load the fleet: ${e instanceof Error ? e.message : String(e)}`,
    });
    return;
  }
  for (const m of machines) {
    if (getRuntime(m.id)) continue;
    const mod = controllers[m.kind];
    const rt = createRuntime(m, mod ? (ctx) => mod.createSession(ctx) : null);
    registerRuntime(rt);
  }
  fleetStore.setState({ status: 'ready', machines, error: null });
  for (const rt of allRuntimes()) {
    try {
      rt.session?.start();
    } catch (e) {
      rt.log.error('console', `session failed to start: ${e instanceof Error ? e.message : String(e)}`);
    }
  }
  window.addEventListener('pagehide', () => {
    for (const rt of allRuntimes()) rt.session?.stop();
  });
}
