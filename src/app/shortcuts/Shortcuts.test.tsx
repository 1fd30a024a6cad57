// @vitest-environment happy-dom
import { act, cleanup, fireEvent, render, screen } from '@testing-library/react';
import { afterEach, beforeEach, describe, expect, it, vi } from 'vitest';
import type { AnyCommand, CommandDecl } from '../../fleet/commands';
import type { MachineSession, SessionContext } from '../../fleet/contract';
import { createRuntime, fleetStore, registerRuntime, type MachineRuntime } from '../../fleet/fleet';
import { alwaysVisible } from '../../fleet/link';
import type { MachineInfo, MachineSnapshot } from '../../fleet/types';
import { DEFAULT_PREFS, fleetPrefsStore } from '../fleet-views/prefs';
import { choosePauseResume } from './pause';
import { Shortcuts } from './Shortcuts';

const sent: string[] = [];

function commandsFor(ctx: SessionContext): Record<string, AnyCommand> {
  const activity = () => ctx.snapshot.getState().activity;
  const pause: CommandDecl<void> = {
    id: 'fake.pause',
    label: 'Pause',
    hazard: 'job',
    role: 'operator',
    confirm: false,
    available: () => (activity() === 'running' ? true : 'Nothing is running'),
    perform: () => {
      sent.push(`${ctx.machine.id} pause`);
      return Promise.resolve('job paused');
    },
  };
  const resume: CommandDecl<void> = {
    id: 'fake.resume',
    label: 'Resume',
    hazard: 'job',
    role: 'operator',
    confirm: 'Resume the job? The machine moves again.',
    available: () => (activity() === 'paused' ? true : 'Not paused'),
    perform: () => {
      sent.push(`${ctx.machine.id} resume`);
      return Promise.resolve('job resumed');
    },
  };
  const stop: CommandDecl<void> = {
    id: 'fake.stop',
    label: 'Stop',
    hazard: 'stop',
    role: 'operator',
    perform: () => Promise.resolve(),
  };
  return { [pause.id]: pause, [resume.id]: resume, [stop.id]: stop } as Record<string, AnyCommand>;
}

function machine(id: string, name: string): MachineRuntime {
  const info: MachineInfo = { id, name, kind: 'duet', simulated: true };
  const rt = createRuntime(
    info,
    (ctx): MachineSession => ({
      machine: info,
      ctx,
      commands: commandsFor(ctx),
      start: () => undefined,
      stop: () => undefined,
    }),
    { visibility: alwaysVisible, principal: () => ({ name: 'olga', role: 'operator' }) },
  );
  registerRuntime(rt);
  return rt;
}

const press = (key: string, init: KeyboardEventInit = {}, target: Element = document.body) =>
  act(() => {
    fireEvent.keyDown(target, { key, ...init });
  });

function online(rt: MachineRuntime, patch: Partial<MachineSnapshot>): void {
  rt.snapshot.setState({ link: 'online', updatedAt: Date.now(), ...patch });
}

describe('keyboard shortcuts', () => {
  let a: MachineRuntime;
  let b: MachineRuntime;
  let c: MachineRuntime;
  beforeEach(() => {
    // The clock of the `g` sequences and of the data's freshness: still unless a test moves it.
    vi.useFakeTimers({ toFake: ['Date'] });
    vi.setSystemTime(new Date('2026-11-21T10:00:00Z'));
    sent.length = 0;
    a = machine('sc-a', 'Charlie');
    b = machine('sc-b', 'Alpha');
    c = machine('sc-c', 'Bravo');
    fleetStore.setState({ status: 'ready', error: null, machines: [a.info, b.info, c.info] });
    fleetPrefsStore.setState(DEFAULT_PREFS, true);
    history.replaceState(null, '', '/m/sc-a');
  });
  afterEach(() => {
    cleanup();
    vi.useRealTimers();
    history.replaceState(null, '', '/');
  });

  it('p asks before pausing the machine on screen; Cancel sends nothing, Yes sends it once', async () => {
    online(a, { activity: 'running' });
    render(<Shortcuts />);
    press('p');
    const dialog = screen.getByTestId('confirm-dialog');
    expect(dialog.textContent).toContain('Pause Charlie?');
    expect(sent).toEqual([]);
    // Focus is on Cancel, not on the button that sends.
    expect(document.activeElement?.textContent).toBe('Cancel');
    fireEvent.click(screen.getByText('Cancel'));
    expect(screen.queryByTestId('confirm-dialog')).toBeNull();
    expect(sent).toEqual([]);

    press('p');
    await act(async () => {
      fireEvent.click(screen.getByTestId('confirm-yes'));
      await Promise.resolve();
    });
    expect(sent).toEqual(['sc-a pause']);
    expect(screen.getByTestId('shortcut-message').textContent).toContain('job paused');
  });

  it('p offers resume with the family’s own question when paused, and says why when neither applies', () => {
    online(a, { activity: 'paused' });
    render(<Shortcuts />);
    press('p');
    expect(screen.getByTestId('confirm-dialog').textContent).toContain(
      'Resume the job? The machine moves again.',
    );
    fireEvent.click(screen.getByText('Cancel'));
    online(a, { activity: 'idle' });
    press('p');
    expect(screen.queryByTestId('confirm-dialog')).toBeNull();
    expect(screen.getByTestId('shortcut-message').textContent).toContain('Nothing is running');
    expect(sent).toEqual([]);
  });

  it('does nothing while typing, with a modifier, or while a dialog is open', () => {
    online(a, { activity: 'running' });
    render(
      <>
        <input data-testid="field" />
        <Shortcuts />
      </>,
    );
    press('p', {}, screen.getByTestId('field'));
    press('p', { ctrlKey: true });
    press('?', { altKey: true });
    expect(screen.queryByTestId('confirm-dialog')).toBeNull();
    expect(screen.queryByTestId('shortcuts-help')).toBeNull();
    press('?');
    expect(screen.getByTestId('shortcuts-help').textContent).toContain('Go to the alarm centre');
    // The help sheet is a dialog: p does nothing behind it.
    press('p');
    expect(screen.queryByTestId('confirm-dialog')).toBeNull();
  });

  it('never leaves focus on a stop control', async () => {
    online(a, { activity: 'running' });
    render(
      <>
        <button data-stop="true" data-testid="estop">
          Stop
        </button>
        <Shortcuts />
      </>,
    );
    const estop = screen.getByTestId('estop');
    estop.focus();
    expect(document.activeElement).toBe(estop);
    press('p', {}, estop);
    expect(screen.getByTestId('confirm-dialog')).toBeTruthy();
    expect(document.activeElement).not.toBe(estop);
    // Closing the dialog gives focus back to where it was, never to the stop control.
    await act(async () => {
      fireEvent.click(screen.getByText('Cancel'));
      await Promise.resolve();
    });
    expect(screen.queryByTestId('confirm-dialog')).toBeNull();
    expect(document.activeElement).not.toBe(estop);
  });

  it('j and k walk the machines in the fleet view’s order; g f and g a go to the fleet and the alarms', () => {
    render(<Shortcuts />);
    press('j');
    expect(location.pathname).toBe('/m/sc-b');
    press(']');
    expect(location.pathname).toBe('/m/sc-c');
    press('j');
    expect(location.pathname).toBe('/m/sc-a');
    // Sorted by name: Alpha (b), Bravo (c), Charlie (a).
    fleetPrefsStore.setState({ ...DEFAULT_PREFS, sort: 'name' }, true);
    press('k');
    expect(location.pathname).toBe('/m/sc-c');
    press('[');
    expect(location.pathname).toBe('/m/sc-b');
    press('g');
    vi.advanceTimersByTime(2000);
    press('a');
    // Too late for `g a`.
    expect(location.pathname).toBe('/m/sc-b');
    press('g');
    vi.advanceTimersByTime(1000);
    press('a');
    expect(location.pathname).toBe('/alarms');
    // Not on a machine page: j does nothing.
    press('j');
    expect(location.pathname).toBe('/alarms');
    press('g');
    press('f');
    expect(location.pathname).toBe('/');
  });

  it('finds a family’s pause under its own name (g2core: feedhold) and nothing where there is none', () => {
    const runner = { blockedReason: () => null };
    const feedhold = { id: 'g2core.feedhold', label: 'Feedhold', confirm: false } as unknown as AnyCommand;
    expect(choosePauseResume({ [feedhold.id]: feedhold }, runner, 'Router')).toMatchObject({
      kind: 'send',
      command: feedhold,
      question: 'Feedhold Router?',
    });
    expect(choosePauseResume({}, runner, 'Plasma')).toEqual({
      kind: 'none',
      reason: 'Plasma cannot be paused from the console.',
    });
  });
});
