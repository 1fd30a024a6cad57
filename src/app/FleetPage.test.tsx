// @vitest-environment happy-dom
import { act, cleanup, render, screen, within } from '@testing-library/react';
import { afterEach, beforeEach, describe, expect, it, vi } from 'vitest';
import { registerController } from '../controllers';
import type { ControllerModule, MachineSession, SessionContext } from '../fleet/contract';
import { createRuntime, fleetStore, pendingRuntime, registerRuntime, getRuntime } from '../fleet/fleet';
import { FleetPage } from './FleetPage';
import { alwaysVisible } from '../fleet/link';
import type { MachineInfo } from '../fleet/types';

function fakeModule(kind: 'xtool' | 'duet', TileExtra?: () => never): ControllerModule {
  return {
    kind,
    label: kind === 'xtool' ? 'Fake laser' : 'Fake printer',
    createSession: (ctx: SessionContext): MachineSession => ({
      machine: ctx.machine,
      ctx,
      commands: {},
      start: () => undefined,
      stop: () => undefined,
    }),
    tabs: [],
    ...(TileExtra ? { TileExtra } : {}),
  };
}

const controllers = {
  xtool: fakeModule('xtool', () => {
    throw new Error('tile exploded');
  }),
  duet: fakeModule('duet'),
};
registerController(controllers.xtool);
registerController(controllers.duet);

function addMachine(info: MachineInfo) {
  const mod = info.kind === 'xtool' || info.kind === 'duet' ? controllers[info.kind] : undefined;
  const rt = createRuntime(info, mod ? (c) => mod.createSession(c) : null, { visibility: alwaysVisible });
  registerRuntime(rt);
  return rt;
}

describe('FleetPage', () => {
  beforeEach(() => {
    vi.useFakeTimers({ toFake: ['Date', 'setInterval', 'clearInterval'] });
    vi.setSystemTime(new Date('2026-11-21T10:00:00Z'));
    vi.spyOn(console, 'error').mockImplementation(() => undefined);
  });
  afterEach(() => {
    cleanup();
    vi.useRealTimers();
    vi.restoreAllMocks();
  });

  it('shows one tile per machine with state in words, and one broken tile never blanks the others', () => {
    const broken = { id: 'laser', name: 'Laser', kind: 'xtool' as const, simulated: true };
    const ok = { id: 'printer', name: 'Printer', kind: 'duet' as const, simulated: false };
    addMachine(broken);
    const rt = getRuntime('printer') ?? addMachine(ok);
    rt.snapshot.setState({
      link: 'online',
      activity: 'running',
      activityLabel: 'Printing layer 12',
      job: { name: 'bracket.gcode', progress: 0.42, elapsed: 600, remaining: 1200 },
      updatedAt: Date.now(),
    });
    fleetStore.setState({ status: 'ready', machines: [broken, ok], error: null });
    render(<FleetPage />);
    const tile = screen.getByTestId('tile-printer');
    expect(within(tile).getByTestId('tile-activity').textContent).toBe('Running');
    expect(within(tile).getByText('bracket.gcode')).toBeTruthy();
    expect(within(tile).getByText('42%')).toBeTruthy();
    expect(within(tile).getByText('20 min 00 s left')).toBeTruthy();
    // The broken machine's tile shows its error; the summary still counts the good one.
    expect(screen.getByTestId('error-boundary').textContent).toContain('tile exploded');
    expect(screen.getByTestId('summary-running').textContent).toBe('1 running');
  });

  it('reads live while the data is fresh, then its age, and marks data older than 10 s as stale', () => {
    const m = { id: 'stale-one', name: 'Stale', kind: 'duet' as const, simulated: false };
    const rt = addMachine(m);
    rt.snapshot.setState({ link: 'online', activity: 'idle', activityLabel: 'Idle', updatedAt: Date.now() });
    fleetStore.setState({ status: 'ready', machines: [m], error: null });
    render(<FleetPage />);
    const age = () => within(screen.getByTestId('tile-stale-one')).getByTestId('data-age');
    expect(age().dataset.stale).toBe('false');
    expect(age().textContent).toBe('live');
    act(() => {
      vi.advanceTimersByTime(5_000);
    });
    expect(age().textContent).toBe('updated 5 sec. ago');
    act(() => {
      vi.advanceTimersByTime(6_000);
    });
    expect(age().dataset.stale).toBe('true');
    expect(age().textContent).toContain('stale');
  });

  it('before its session answers, a tile shows the console server reading, then the session data', () => {
    const m: MachineInfo = {
      id: 'first-screen',
      name: 'Table',
      kind: 'touchcut',
      simulated: true,
      watch: {
        state: 'running',
        job: 'FLANGE.nc',
        progress: 0.25,
        alarm: 'Torch <b>collision</b>',
        alarmSeverity: 'critical',
        ageMs: 3000,
      },
    };
    // No family code yet: the runtime waits for its session (boot.ts makes it so).
    const rt = pendingRuntime(m, { visibility: alwaysVisible });
    registerRuntime(rt);
    fleetStore.setState({ status: 'ready', machines: [m], error: null });
    render(<FleetPage />);
    const tile = () => screen.getByTestId('tile-first-screen');
    // The server's reading carries a critical alarm: it overrides the state chip (issue 33).
    expect(within(tile()).getByTestId('tile-activity').textContent).toBe('Alarm · was running');
    expect(within(tile()).getByTestId('tile-label').textContent).toBe(
      'Read by the console server 3 s ago · connecting…',
    );
    expect(within(tile()).getByText('FLANGE.nc')).toBeTruthy();
    expect(within(tile()).getByText('25%')).toBeTruthy();
    // Controller text is text: the markup is shown as written, never parsed.
    expect(within(tile()).getByTestId('tile-alarm').textContent).toContain('Torch <b>collision</b>');
    expect(tile().querySelector('b')).toBeNull();
    // Counted once, in alarm (the counts are a partition of the fleet).
    expect(screen.getByTestId('summary-alarm').textContent).toBe('1 in alarm');
    expect(screen.getByTestId('summary-running').textContent).toBe('0 running');
    expect(within(tile()).getByTestId('tile-link').textContent).toMatch(/connecting/i);
    // The session's first answer: its own data replaces the server's reading.
    act(() => {
      rt.snapshot.setState({
        link: 'online',
        activity: 'idle',
        activityLabel: 'Ready',
        job: null,
        updatedAt: Date.now(),
      });
    });
    expect(within(tile()).getByTestId('tile-activity').textContent).toBe('Idle');
    expect(within(tile()).getByTestId('tile-label').textContent).toBe('Ready');
    expect(within(tile()).queryByTestId('tile-alarm')).toBeNull();
    expect(screen.getByTestId('summary-running').textContent).toBe('0 running');
    expect(screen.getByTestId('summary-alarm').textContent).toBe('0 in alarm');
    expect(screen.getByTestId('summary-idle').textContent).toBe('1 idle');
  });

  it('a session that fails before any answer shows its failure, not the server reading', () => {
    const m: MachineInfo = {
      id: 'first-fail',
      name: 'Mill',
      kind: 'duet',
      simulated: false,
      watch: { state: 'running', job: null, progress: null, alarm: null, ageMs: null },
    };
    const rt = addMachine(m);
    fleetStore.setState({ status: 'ready', machines: [m], error: null });
    render(<FleetPage />);
    const tile = () => screen.getByTestId('tile-first-fail');
    expect(within(tile()).getByTestId('tile-label').textContent).toBe(
      'Read by the console server · connecting…',
    );
    act(() => {
      rt.snapshot.setState({
        link: 'offline',
        activity: 'offline',
        activityLabel: 'Cannot reach the machine',
      });
    });
    expect(within(tile()).getByTestId('tile-activity').textContent).toBe('Offline');
    expect(within(tile()).getByTestId('tile-label').textContent).toBe('Cannot reach the machine');
  });
});
