import { z } from 'zod';
import { controllers } from '../controllers';
import { authStore } from '../fleet/auth';
import { commandHistory } from '../fleet/commands';
import { createRuntime, fleetStore, getRuntime, registerRuntime, allRuntimes } from '../fleet/fleet';
import { MACHINE_KINDS, type MachineInfo } from '../fleet/types';
import { CONSOLE_HEADERS } from '../fleet/origin';
import { fetchSession, trackActivity } from './auth/api';
import { simulatorFor, startDemo } from './demo';

const MachinesAnswer = z.object({
  machines: z.array(
    z.object({
      id: z.string(),
      name: z.string(),
      kind: z.enum(MACHINE_KINDS),
      simulated: z.boolean(),
    }),
  ),
  /** True when the gateway serves its built-in demo fleet (no machines file). */
  demo: z.boolean().optional(),
});

export const demoState = {
  mode: 'none' as 'service-worker' | 'fallback' | 'none',
  error: undefined as string | undefined,
};

export async function loadSession(): Promise<void> {
  try {
    await fetchSession();
  } catch {
    // A gateway without access control: behave as open mode, and say so in the banner.
    authStore.setState({ mode: 'open', user: null });
  }
  trackActivity();
}

/** Loads the fleet, starts demo simulators, creates and starts one session per machine. */
export async function boot(): Promise<void> {
  await loadSession();
  let machines: MachineInfo[];
  let builtInDemo = false;
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
    builtInDemo = parsed.data.demo === true;
  } catch (e) {
    fleetStore.setState({
      status: 'error',
      error: `Cannot load the fleet: ${e instanceof Error ? e.message : String(e)}`,
    });
    return;
  }
  const demo = await startDemo(machines);
  demoState.mode = demo.mode;
  demoState.error = demo.error;
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
  // The built-in demo fleet shows work in progress: each simulator's "demo" control (if it has
  // one) starts a job, as an operator at the machine would.
  if (builtInDemo) {
    for (const m of machines) {
      const demoControl = simulatorFor(m.id)
        ?.controls()
        .find((c) => c.id === 'demo');
      if (demoControl) setTimeout(() => demoControl.run(), 1500);
    }
  }
  // Commands to simulated machines are answered in the page, so the gateway never sees them:
  // report them so the audit log is complete (the gateway accepts this only for simulated ids).
  const simulatedIds = new Set(machines.filter((m) => m.simulated).map((m) => m.id));
  let lastSeq = 0;
  commandHistory.subscribe((s) => {
    for (const rec of [...s.records].reverse()) {
      if (rec.seq <= lastSeq) continue;
      lastSeq = rec.seq;
      if (!simulatedIds.has(rec.machineId)) continue;
      void fetch('/api/audit/client', {
        method: 'POST',
        headers: { 'Content-Type': 'application/json', ...CONSOLE_HEADERS },
        credentials: 'same-origin',
        body: JSON.stringify({
          machine: rec.machineId,
          command: rec.commandId,
          label: rec.label,
          ok: rec.ok,
          result: rec.result,
        }),
      }).catch(() => undefined);
    }
  });
  window.addEventListener('pagehide', () => {
    for (const rt of allRuntimes()) rt.session?.stop();
  });
}
