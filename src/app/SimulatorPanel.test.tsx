// @vitest-environment happy-dom
import { act, cleanup, fireEvent, render, screen, waitFor } from '@testing-library/react';
import { http, HttpResponse } from 'msw';
import { setupServer } from 'msw/node';
import { afterAll, afterEach, beforeAll, beforeEach, describe, expect, it } from 'vitest';
import { FaultySimulator } from '../fleet/sim';
import { simSetSchema } from '../fleet/sim-panel';
import { simPanel } from '../../gateway/sim-api';
import type { MachineEntry } from '../../gateway/machines';
import { SimulatorPanel } from './SimulatorPanel';

/**
 * The Simulator tab renders what the gateway says (`GET /api/sim/<id>`, here the gateway's own
 * `simPanel` over a simulator) and sends each change as `POST /api/sim/<id>` with the console
 * header. The gateway's side, attacks included, is tested in gateway/sim-api.test.ts.
 */

const machine: MachineEntry = {
  id: 'demo',
  name: 'Demo',
  kind: 'xtool',
  simulated: true,
  url: null,
  wsUrl: null,
  secrets: {},
};

let pressed: string[] = [];
let posts: Array<{ body: unknown; header: string | null }> = [];
let refuse = false;
let sim: FaultySimulator;

const server = setupServer(
  http.get('http://shopdeck.test/api/sim/demo', () => HttpResponse.json(simPanel(machine, sim))),
  http.post('http://shopdeck.test/api/sim/demo', async ({ request }) => {
    const body: unknown = await request.json();
    posts.push({ body, header: request.headers.get('x-shopdeck') });
    if (refuse)
      return HttpResponse.json(
        { error: 'the simulator is for supervisors', needs: 'supervisor' },
        { status: 403 },
      );
    const set = simSetSchema.parse(body);
    if (set.group === 'world')
      sim
        .controls()
        .find((c) => c.id === set.id)
        ?.run();
    if (set.group === 'faults' && set.id !== 'closeSockets') sim.setFaults({ [set.id]: set.value });
    return HttpResponse.json(simPanel(machine, sim));
  }),
);

beforeAll(() => server.listen({ onUnhandledRequest: 'error' }));
afterAll(() => server.close());
beforeEach(() => {
  pressed = [];
  posts = [];
  refuse = false;
  sim = new FaultySimulator({
    kind: 'xtool',
    fetch: () => Promise.resolve(new Response('{}')),
    controls: () => [{ id: 'flame', label: 'Flame under the laser', run: () => pressed.push('flame') }],
    dispose: () => undefined,
  });
});
afterEach(() => cleanup());

describe('SimulatorPanel', () => {
  it('shows the gateway’s controls and says the simulator runs in the server', async () => {
    render(<SimulatorPanel id="demo" />);
    expect(await screen.findByTestId('sim-control-flame')).toBeTruthy();
    expect(screen.getByRole('button', { name: 'Flame under the laser' })).toBeTruthy();
    expect((screen.getByTestId('fault-drop') as HTMLInputElement).checked).toBe(false);
    expect((screen.getByTestId('fault-latency') as HTMLSelectElement).value).toBe('0');
    expect(screen.getByTestId('fault-5xx')).toBeTruthy();
    expect(screen.getByTestId('fault-malformed')).toBeTruthy();
    expect(screen.getByTestId('fault-close-sockets')).toBeTruthy();
    expect(screen.getByTestId('sim-reset')).toBeTruthy();
    expect(screen.getByTestId('sim-panel').textContent).toMatch(/runs in the console’s server/);
  });

  it('sends each change with the console header and shows the simulator’s new state', async () => {
    render(<SimulatorPanel id="demo" />);
    fireEvent.click(await screen.findByTestId('sim-control-flame'));
    await waitFor(() => expect(pressed).toEqual(['flame']));
    const drop = screen.getByTestId('fault-drop') as HTMLInputElement;
    fireEvent.click(drop);
    expect(drop.checked).toBe(true);
    await waitFor(() => expect(sim.faults.drop).toBe(true));
    fireEvent.change(screen.getByTestId('fault-latency'), { target: { value: '1000' } });
    await waitFor(() => expect(sim.faults.latencyMs).toBe(1000));
    fireEvent.click(screen.getByTestId('sim-reset'));
    await waitFor(() => expect(posts).toHaveLength(4));
    expect(posts).toEqual([
      { body: { group: 'world', id: 'flame' }, header: '1' },
      { body: { group: 'faults', id: 'drop', value: true }, header: '1' },
      { body: { group: 'faults', id: 'latencyMs', value: 1000 }, header: '1' },
      { body: { group: 'simulator', id: 'reset' }, header: '1' },
    ]);
  });

  it('shows a refusal and the simulator’s real state again', async () => {
    render(<SimulatorPanel id="demo" />);
    const drop = (await screen.findByTestId('fault-drop')) as HTMLInputElement;
    refuse = true;
    await act(async () => {
      fireEvent.click(drop);
      await Promise.resolve();
    });
    expect(await screen.findByTestId('sim-error')).toBeTruthy();
    expect(screen.getByTestId('sim-error').textContent).toMatch(/for supervisors/);
    await waitFor(() => expect((screen.getByTestId('fault-drop') as HTMLInputElement).checked).toBe(false));
  });
});
