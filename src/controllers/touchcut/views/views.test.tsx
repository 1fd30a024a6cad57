// @vitest-environment happy-dom
import { act, cleanup, fireEvent, render, screen, waitFor, within } from '@testing-library/react';
import { setupServer } from 'msw/node';
import { afterAll, afterEach, beforeAll, beforeEach, describe, expect, it } from 'vitest';
import { createContext } from '../../../fleet/fleet';
import { authStore } from '../../../fleet/auth';
import { alwaysVisible } from '../../../fleet/link';
import { simulatorHandlers } from '../../../fleet/msw';
import { setApiOrigin } from '../../../fleet/origin';
import { TouchcutSession } from '../session';
import { SIM_MONITOR_API_KEY, TouchcutSimulator } from '../sim/simulator';
import { viaGateway, type GatewayStandIn } from '../testkit';
import { LoginForm } from './LoginForm';
import { MonitorView } from './MonitorView';
import { ScreenView } from './ScreenView';
import { StatsView } from './StatsView';
import { StatusView } from './Overview';

let sim: TouchcutSimulator;
let gw: GatewayStandIn;
let session: TouchcutSession;
const server = setupServer();

beforeAll(() => {
  setApiOrigin('http://shopdeck.test');
  server.listen({ onUnhandledRequest: 'error' });
});
afterAll(() => server.close());

function start(apiKey: string | undefined) {
  sim = new TouchcutSimulator({ id: 'tcv', name: 'Plasma' });
  sim.autoOperator = false;
  gw = viaGateway(sim, apiKey);
  server.resetHandlers(...simulatorHandlers('tcv', gw));
  const ctx = createContext(
    { id: 'tcv', name: 'Plasma', kind: 'touchcut', simulated: true },
    { visibility: alwaysVisible, principal: () => ({ name: 'sam', role: 'supervisor' }) },
  );
  session = new TouchcutSession(ctx);
  session.start();
}

beforeEach(() => undefined);
afterEach(() => {
  cleanup();
  session.stop();
  sim.dispose();
});

describe('touchcut views', () => {
  it('login form logs in and the status view shows the machine', async () => {
    start(undefined);
    await waitFor(() => expect(session.ctx.snapshot.getState().link).toBe('needs-login'));
    render(<LoginForm session={session} />);
    expect(screen.getByTestId('touchcut-sim-users').textContent).toMatch(/operator \/ operator/);
    fireEvent.change(screen.getByTestId('touchcut-username'), { target: { value: 'operator' } });
    fireEvent.change(screen.getByTestId('touchcut-password'), { target: { value: 'bad' } });
    fireEvent.click(screen.getByTestId('touchcut-login-submit'));
    expect((await screen.findByTestId('touchcut-login-error')).textContent).toBe('Wrong TouchCut password');
    fireEvent.change(screen.getByTestId('touchcut-password'), { target: { value: 'operator' } });
    fireEvent.click(screen.getByTestId('touchcut-login-submit'));
    await waitFor(() => expect(session.ctx.snapshot.getState().link).toBe('online'));
    cleanup();
    render(<StatusView session={session} />);
    expect((await screen.findByTestId('touchcut-state')).textContent).toBe('Idle');
    expect(screen.getByTestId('touchcut-user').textContent).toBe('operator');
    expect(screen.getByTestId('touchcut-read-only')).toBeTruthy();
    expect(within(screen.getByTestId('touchcut-positions')).getAllByRole('row').length).toBeGreaterThan(3);
  });

  it('the status view shows the login the gateway holds (user, expiry) and logs it out', async () => {
    start(SIM_MONITOR_API_KEY);
    await waitFor(() => expect(session.ctx.snapshot.getState().link).toBe('online'));
    render(<StatusView session={session} />);
    fireEvent.click(await screen.findByTestId('touchcut-login-open'));
    fireEvent.change(screen.getByTestId('touchcut-username'), { target: { value: 'admin' } });
    fireEvent.change(screen.getByTestId('touchcut-password'), { target: { value: 'admin' } });
    fireEvent.click(screen.getByTestId('touchcut-login-submit'));
    expect((await screen.findByTestId('touchcut-user')).textContent).toBe('admin');
    expect(screen.getByTestId('touchcut-login-expiry').textContent).toMatch(/login valid until/);
    expect(gw.heldToken).not.toBeNull();
    expect(document.body.innerHTML).not.toContain(gw.heldToken);
    fireEvent.click(screen.getByTestId('touchcut-logout'));
    await screen.findByTestId('touchcut-login-open');
    expect(screen.queryByTestId('touchcut-user')).toBeNull();
    expect(gw.heldToken).toBeNull();
  });

  it('a viewer is told that logging the machine in is for an operator, and may retry without a login', async () => {
    authStore.setState({ mode: 'secured', user: { name: 'vic', role: 'viewer', machines: null } });
    try {
      start(undefined);
      await waitFor(() => expect(session.ctx.snapshot.getState().link).toBe('needs-login'));
      render(<LoginForm session={session} />);
      expect(screen.getByTestId('touchcut-login-needs-operator').textContent).toMatch(/operator/);
      expect(screen.queryByTestId('touchcut-password')).toBeNull();
      expect(screen.getByRole('button', { name: 'Try again without a login' })).toBeTruthy();
    } finally {
      authStore.setState({ mode: 'unknown', user: null });
    }
  });

  it('statistics: last week shows the consumables with totals', async () => {
    start(SIM_MONITOR_API_KEY);
    await waitFor(() => expect(session.ctx.snapshot.getState().link).toBe('online'));
    render(<StatsView session={session} />);
    fireEvent.click(screen.getByTestId('stats-preset-lastWeek'));
    await waitFor(() => expect(screen.getByTestId('stats-days').textContent).toMatch(/\(7 days\)/));
    const table = screen.getByTestId('stats-consumable-totals');
    const text = table.textContent ?? '';
    expect(text).toMatch(/Electrode/);
    expect(text).toMatch(/Nozzle/);
    expect(screen.getByTestId('stats-user-bars')).toBeTruthy();
    const last = gw.fromBrowser.filter((r) => r.path.includes('/stats')).at(-1);
    expect(last?.path).toMatch(/start-date=\d{4}-\d{2}-\d{2}&end-before-date=\d{4}-\d{2}-\d{2}/);
  });

  it('monitor asks only for the sections on screen', async () => {
    start(SIM_MONITOR_API_KEY);
    await waitFor(() => expect(session.ctx.snapshot.getState().link).toBe('online'));
    render(<MonitorView session={session} />);
    await waitFor(() =>
      expect(within(screen.getByTestId('touchcut-axes')).getAllByRole('row').length).toBe(4),
    );
    const q = decodeURIComponent(
      gw.fromBrowser.filter((r) => r.path.includes('/monitor')).at(-1)?.path ?? '',
    );
    expect(q).toContain('fields=axes.*,io.din,io.dout');
    fireEvent.click(screen.getByRole('button', { name: 'Axes' }));
    await waitFor(() => {
      const p = decodeURIComponent(
        gw.fromBrowser.filter((r) => r.path.includes('/monitor')).at(-1)?.path ?? '',
      );
      expect(p).toContain('fields=io.din,io.dout');
    });
  });

  it('screen shows the live image with its age and can pause', async () => {
    start(SIM_MONITOR_API_KEY);
    await waitFor(() => expect(session.ctx.snapshot.getState().link).toBe('online'));
    render(<ScreenView session={session} />);
    await screen.findByTestId('screen-image');
    expect(screen.getByTestId('screen-age').textContent).toMatch(/image from \d+ sec\.? ago/);
    act(() => {
      fireEvent.click(screen.getByTestId('screen-pause'));
    });
    expect(session.screenshot.watching).toBe(false);
    expect(screen.getByTestId('screen-age').textContent).toMatch(/^Paused/);
  });
});
