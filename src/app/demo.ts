import { families } from '../controllers/families';
import { simulatorHandlers } from '../fleet/msw';
import { FaultySimulator } from '../fleet/sim';
import type { MachineInfo } from '../fleet/types';

/**
 * Demo mode: simulated machines answer `/machines/<id>/...` inside the page through msw.
 * Everything they say is simulated; the UI says so on every simulated machine.
 */
const simulators = new Map<string, FaultySimulator>();

export function simulatorFor(id: string): FaultySimulator | undefined {
  return simulators.get(id);
}

export async function startDemo(
  machines: MachineInfo[],
): Promise<{ mode: 'service-worker' | 'fallback' | 'none'; error?: string }> {
  const simulated = machines.filter((m) => m.simulated);
  if (simulated.length === 0) return { mode: 'none' };
  const handlers = [];
  for (const m of simulated) {
    const fam = families[m.kind];
    if (!fam) continue;
    const sim = new FaultySimulator(fam.createSimulator({ id: m.id, name: m.name }));
    simulators.set(m.id, sim);
    handlers.push(...simulatorHandlers(m.id, sim));
  }
  const { setupWorker } = await import('msw/browser');
  const worker = setupWorker(...handlers);
  const hasSw = typeof navigator !== 'undefined' && 'serviceWorker' in navigator && window.isSecureContext;
  try {
    await worker.start({
      serviceWorker: { url: '/mockServiceWorker.js' },
      onUnhandledRequest: 'bypass',
      quiet: true,
    });
    return { mode: hasSw ? 'service-worker' : 'fallback' };
  } catch (e) {
    return { mode: 'none', error: e instanceof Error ? e.message : String(e) };
  }
}
