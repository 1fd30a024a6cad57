// @vitest-environment happy-dom
import { act, cleanup, fireEvent, render, screen, within } from '@testing-library/react';
import { afterEach, beforeEach, describe, expect, it, vi } from 'vitest';
import { registerController } from '../../controllers';
import type { ControllerModule, MachineSession, SessionContext } from '../../fleet/contract';
import { createRuntime, fleetStore, registerRuntime, type MachineRuntime } from '../../fleet/fleet';
import { alwaysVisible } from '../../fleet/link';
import type { MachineInfo } from '../../fleet/types';
import { FleetPage } from '../FleetPage';
import { DEFAULT_PREFS, fleetPrefsStore, PREFS_KEY } from './prefs';

/** Renders of each machine's tile body (its TileExtra renders with it). */
const renders = new Map<string, number>();

function fakeModule(kind: 'prunt' | 'touchcut'): ControllerModule {
  return {
    kind,
    label: kind,
    createSession: (ctx: SessionContext): MachineSession => ({
      machine: ctx.machine,
      ctx,
      commands: {},
      start: () => undefined,
      stop: () => undefined,
    }),
    tabs: [],
    TileExtra: ({ session }: { session: MachineSession }) => {
      renders.set(session.machine.id, (renders.get(session.machine.id) ?? 0) + 1);
      return null;
    },
  };
}
const modules = { prunt: fakeModule('prunt'), touchcut: fakeModule('touchcut') };
registerController(modules.prunt);
registerController(modules.touchcut);

function add(info: MachineInfo): MachineRuntime {
  const mod = info.kind === 'prunt' || info.kind === 'touchcut' ? modules[info.kind] : null;
  const rt = createRuntime(info, mod ? (c) => mod.createSession(c) : null, { visibility: alwaysVisible });
  registerRuntime(rt);
  rt.snapshot.setState({ link: 'online', activity: 'idle', activityLabel: 'Idle', updatedAt: Date.now() });
  return rt;
}

const ids = (root: HTMLElement, prefix: string) =>
  [...root.querySelectorAll(`[data-testid^="${prefix}"]`)].map((e) =>
    (e.getAttribute('data-testid') ?? '').slice(prefix.length),
  );

describe('fleet views', () => {
  let rts: MachineRuntime[];
  beforeEach(() => {
    vi.useFakeTimers({ toFake: ['Date', 'setInterval', 'clearInterval'] });
    vi.setSystemTime(new Date('2026-11-21T10:00:00Z'));
    renders.clear();
    localStorage.clear();
    fleetPrefsStore.setState(DEFAULT_PREFS, true);
    history.replaceState(null, '', '/');
    rts = [
      add({ id: 'fv-p1', name: 'Printer 1', kind: 'prunt', simulated: false, group: 'Bay 2' }),
      add({ id: 'fv-cut', name: 'Cutter', kind: 'touchcut', simulated: false, group: 'Bay 1' }),
      add({ id: 'fv-p2', name: 'Printer 2', kind: 'prunt', simulated: false }),
    ];
    fleetStore.setState({ status: 'ready', error: null, machines: rts.map((r) => r.info) });
  });
  afterEach(() => {
    cleanup();
    vi.useRealTimers();
  });

  it('sorts by state as states change, without re-rendering the other tiles', () => {
    render(<FleetPage />);
    const tiles = screen.getByTestId('fleet-tiles');
    expect(ids(tiles, 'tile-').filter((i) => i.startsWith('fv-'))).toEqual(['fv-p1', 'fv-cut', 'fv-p2']);
    fireEvent.change(screen.getByTestId('fleet-sort'), { target: { value: 'state' } });
    expect(location.search).toBe('?sort=state');
    expect(JSON.parse(localStorage.getItem(PREFS_KEY) ?? '{}')).toMatchObject({ sort: 'state' });
    const before = new Map(renders);
    act(() => rts[2]?.snapshot.setState({ activity: 'running', activityLabel: 'Printing' }));
    expect(ids(tiles, 'tile-').filter((i) => i.startsWith('fv-'))).toEqual(['fv-p2', 'fv-p1', 'fv-cut']);
    // Only the machine that changed rendered again.
    expect(renders.get('fv-p1')).toBe(before.get('fv-p1'));
    expect(renders.get('fv-cut')).toBe(before.get('fv-cut'));
    expect(renders.get('fv-p2')).toBe((before.get('fv-p2') ?? 0) + 1);
  });

  it('filters by state, family and name, and says how many are shown', () => {
    render(<FleetPage />);
    act(() => rts[1]?.snapshot.setState({ activity: 'alarm', activityLabel: 'Torch collision' }));
    fireEvent.change(screen.getByTestId('fleet-state'), { target: { value: 'alarm' } });
    expect(ids(screen.getByTestId('fleet-tiles'), 'tile-')).toContain('fv-cut');
    expect(screen.queryByTestId('tile-fv-p1')).toBeNull();
    expect(screen.getByTestId('fleet-shown').textContent).toContain('1 of 3 shown');
    fireEvent.click(screen.getByTestId('fleet-clear'));
    fireEvent.change(screen.getByTestId('fleet-family'), { target: { value: 'prunt' } });
    fireEvent.change(screen.getByTestId('fleet-filter'), { target: { value: 'printer 2' } });
    expect(ids(screen.getByTestId('fleet-tiles'), 'tile-').filter((i) => i.startsWith('fv-'))).toEqual([
      'fv-p2',
    ]);
    expect(location.search).toBe('?family=prunt&q=printer+2');
    fireEvent.change(screen.getByTestId('fleet-filter'), { target: { value: 'nothing' } });
    expect(screen.getByText('No machine matches this filter.')).toBeTruthy();
  });

  it('shows the dense list grouped by the machines file group, and opens a bookmarked view', async () => {
    history.replaceState(null, '', '/?view=list&group=group');
    render(<FleetPage />);
    const table = await screen.findByTestId('fleet-list');
    const groups = [...table.querySelectorAll('tbody')].map((t) => t.querySelector('th')?.textContent);
    expect(groups).toEqual(['Bay 1 (1)', 'Bay 2 (1)', 'No group (1)']);
    const row = within(screen.getByTestId('row-fv-p1'));
    expect(row.getByRole('link', { name: 'Printer 1' }).getAttribute('href')).toBe('/m/fv-p1');
    expect(row.getByTestId('row-group').textContent).toBe('Bay 2');
    expect(row.getByTestId('row-activity').textContent).toBe('Idle');
    expect(row.getByTestId('row-link').textContent).toBe('Online');
    // The bookmark became this browser's view.
    expect(fleetPrefsStore.getState()).toMatchObject({ view: 'list', groupBy: 'group' });
    fireEvent.click(screen.getByTestId('view-grid'));
    expect(location.search).toBe('?group=group');
    expect(screen.getByTestId('fleet-group-group:Bay 1').textContent).toContain('Cutter');
    expect(within(screen.getByTestId('tile-fv-cut')).getByTestId('tile-group').textContent).toContain(
      'Bay 1',
    );
  });
});
