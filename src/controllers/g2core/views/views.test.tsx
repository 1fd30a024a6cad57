// @vitest-environment happy-dom
import { act, cleanup, fireEvent, render, screen, waitFor, within } from '@testing-library/react';
import { setupServer } from 'msw/node';
import { afterAll, afterEach, beforeAll, beforeEach, describe, expect, it } from 'vitest';
import { createContext } from '../../../fleet/fleet';
import { alwaysVisible } from '../../../fleet/link';
import { simulatorHandlers } from '../../../fleet/msw';
import { G2coreSession } from '../session';
import { G2coreSimulator } from '../sim/simulator';
import { OverviewTab } from './Overview';
import { SettingsTab } from './Settings';
import { ConsoleTab } from './Console';
import { JobsTab } from './Jobs';

let sim: G2coreSimulator;
let session: G2coreSession;
const server = setupServer();

beforeAll(() => server.listen({ onUnhandledRequest: 'error' }));
afterAll(() => server.close());
beforeEach(() => {
  sim = new G2coreSimulator({ id: 'cnc', name: 'CNC' });
  server.resetHandlers(...simulatorHandlers('cnc', sim));
  const ctx = createContext(
    { id: 'cnc', name: 'CNC', kind: 'g2core', simulated: true },
    { visibility: alwaysVisible, principal: () => ({ name: 't', role: 'supervisor' }) },
  );
  session = new G2coreSession(ctx);
  session.start();
});
afterEach(() => {
  cleanup();
  session.stop();
  sim.dispose();
});

describe('g2core views', () => {
  it('overview: state in words, DRO of enabled axes, version', async () => {
    render(<OverviewTab session={session} />);
    await waitFor(() => expect(screen.getByTestId('g2-stat').textContent).toBe('Ready'));
    expect(screen.getByTestId('dro-x-work').textContent).toBe('0.000');
    expect(screen.queryByTestId('dro-a')).toBeNull();
    await waitFor(() =>
      expect(within(screen.getByTestId('g2-version')).getByText('100.12-14-g375c-dirty')).toBeTruthy(),
    );
    expect(screen.getByTestId('g2-modal').textContent).toContain('G21 millimeters');
    act(() =>
      sim
        .controls()
        .find((c) => c.id === 'shutdown')!
        .run(),
    );
    await waitFor(() => expect(screen.getByTestId('g2-stat').textContent).toBe('Shutdown'));
    expect(screen.getByTestId('alarm-g2core-shutdown').textContent).toMatch(/What clears it/);
  });

  it('settings: edit X max velocity, read-only keys, refusal text', async () => {
    render(<SettingsTab session={session} />);
    await waitFor(() => expect(screen.getByTestId('g2-group-g92')).toBeTruthy());
    const input = await screen.findByTestId('g2-input-x-vm');
    fireEvent.change(input, { target: { value: '32000' } });
    fireEvent.click(screen.getByTestId('g2-save-x.vm'));
    await waitFor(() => expect(sim.cfg.x!.vm).toBe(32000));
    fireEvent.click(screen.getByTestId('g2-group-sys'));
    await waitFor(() => expect(screen.getByTestId('g2-readonly-sys.fb')).toBeTruthy());
    fireEvent.click(screen.getByTestId('g2-group-g92'));
    const g92x = await screen.findByTestId('g2-input-g92-x');
    fireEvent.change(g92x, { target: { value: '3' } });
    fireEvent.click(screen.getByTestId('g2-save-g92.x'));
    await waitFor(() =>
      expect(screen.getByTestId('g2-error-g92.x').textContent).toContain('Parameter is read-only'),
    );
    expect(screen.getByTestId('g2-readonly-g92.x')).toBeTruthy();
  });

  it('console: a refused line shows the status text', async () => {
    render(<ConsoleTab session={session} />);
    await waitFor(() => expect(screen.getByTestId('g2-stat').textContent).toBe('Ready'));
    fireEvent.change(screen.getByTestId('g2-console-input'), { target: { value: 'G999' } });
    fireEvent.click(screen.getByTestId('g2-console-send'));
    await waitFor(() =>
      expect(screen.getByTestId('g2-console-history').textContent).toContain('Gcode command unsupported'),
    );
  });
  it('console: says on screen why MDI is not available while a job runs', async () => {
    render(<ConsoleTab session={session} />);
    await waitFor(() => expect(screen.getByTestId('g2-stat').textContent).toBe('Ready'));
    expect(screen.queryByTestId('g2-whynot-g2core.mdi')).toBeNull();
    act(() =>
      sim
        .controls()
        .find((c) => c.id === 'demo')!
        .run(),
    );
    await waitFor(() =>
      expect(screen.getByTestId('g2-whynot-g2core.mdi').textContent).toMatch(
        /Not while job "demo-pocket.nc" runs/,
      ),
    );
  });
  it('jobs: the status text of a failed job is on screen, not only in a tooltip', async () => {
    render(<JobsTab session={session} />);
    const send = (method: string, path: string, body: unknown) =>
      sim.fetch(new Request(`http://sim${path}`, { method, body: JSON.stringify(body) }), path);
    await send('POST', '/job', { name: 'bad.nc', gcode: 'G21\nG999\n' });
    await send('PUT', '/job/1', { state: 'run' });
    await waitFor(() =>
      expect(screen.getByTestId('g2-job-error-1').textContent).toMatch(/Gcode command unsupported — .*G999/),
    );
    expect(screen.getByTestId('g2-job-state-1').textContent).toContain('error');
  });
});
