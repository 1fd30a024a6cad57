// @vitest-environment happy-dom
import { act, cleanup, render, screen } from '@testing-library/react';
import { afterEach, describe, expect, it, vi } from 'vitest';
import { createStore } from 'zustand/vanilla';
import { IN_DOUBT_AFTER_MS } from '../commands';
import { createContext } from '../fleet';
import { alwaysVisible } from '../link';
import { CommandButton } from '../react';
import { defineCommands } from './commands';

afterEach(cleanup);

/**
 * Issue 12, defect 3: a command button showed "not available" while its runner would send it,
 * because availability read a family store the button did not subscribe to. A button follows
 * every store its command's availability names.
 */
describe('command availability follows the stores it names (defect 3)', () => {
  it('a family-store change alone makes the button available, and unavailable again', () => {
    const ctx = createContext(
      { id: 'x1', name: 'X1', kind: 'xtool', simulated: true },
      { visibility: alwaysVisible, principal: () => ({ name: 'op', role: 'operator' }) },
    );
    ctx.snapshot.setState({ link: 'online', activity: 'idle' });
    const family = createStore(() => ({ fileReady: false }));
    const cmds = defineCommands({ snapshot: ctx.snapshot, family });
    const frame = cmds.define({
      id: 'x.frame',
      label: 'Frame',
      hazard: 'motion',
      role: 'operator',
      confirm: false,
      available: ({ family: f }) => (f.fileReady ? true : 'No file loaded'),
      perform: async () => 'framed',
    });
    render(<CommandButton runner={ctx.commands} snapshot={ctx.snapshot} command={frame} args={undefined} />);
    const button = () => screen.getByRole('button', { name: 'Frame' });
    expect(button().getAttribute('aria-disabled')).toBe('true');
    act(() => family.setState({ fileReady: true })); // the snapshot does not change
    expect(ctx.commands.blockedReason(frame)).toBeNull();
    expect(button().getAttribute('aria-disabled')).toBeNull();
    act(() => family.setState({ fileReady: false }));
    expect(button().getAttribute('aria-disabled')).toBe('true');
    expect(button().getAttribute('title')).toBe('No file loaded');
  });
});

/**
 * Issue 15: while a link is in doubt (reconnecting, or its data stale), commands other than stops
 * are disabled, as they are when offline. Data goes stale with time alone: the button follows it.
 */
describe('commands while the link is in doubt', () => {
  afterEach(() => {
    vi.useRealTimers();
  });

  it('stale data disables every command but stops, by time alone; fresh data enables them again', () => {
    vi.useFakeTimers();
    const ctx = createContext(
      { id: 'x2', name: 'X2', kind: 'xtool', simulated: true },
      { visibility: alwaysVisible, principal: () => ({ name: 'op', role: 'operator' }) },
    );
    ctx.snapshot.setState({ link: 'online', activity: 'running', updatedAt: Date.now() });
    const cmds = defineCommands({ snapshot: ctx.snapshot });
    const pause = cmds.define({
      id: 'x.pause',
      label: 'Pause',
      hazard: 'job',
      role: 'operator',
      confirm: false,
      perform: async () => 'paused',
    });
    const stop = cmds.define({
      id: 'x.stop',
      label: 'Stop',
      hazard: 'stop',
      role: 'operator',
      confirm: false,
      perform: async () => 'stopped',
    });
    render(
      <>
        <CommandButton runner={ctx.commands} snapshot={ctx.snapshot} command={pause} args={undefined} />
        <CommandButton runner={ctx.commands} snapshot={ctx.snapshot} command={stop} args={undefined} />
      </>,
    );
    const button = (name: string) => screen.getByRole('button', { name });
    expect(button('Pause').getAttribute('aria-disabled')).toBeNull();
    act(() => {
      vi.advanceTimersByTime(IN_DOUBT_AFTER_MS - 100);
    });
    expect(button('Pause').getAttribute('aria-disabled')).toBeNull();
    act(() => {
      vi.advanceTimersByTime(200); // nothing but time changes
    });
    expect(button('Pause').getAttribute('aria-disabled')).toBe('true');
    expect(button('Pause').getAttribute('title')).toMatch(/in doubt/);
    expect(button('Stop').getAttribute('aria-disabled')).toBeNull();
    act(() => ctx.snapshot.setState({ updatedAt: Date.now() }));
    expect(button('Pause').getAttribute('aria-disabled')).toBeNull();
    act(() => ctx.snapshot.setState({ link: 'reconnecting' }));
    expect(button('Pause').getAttribute('aria-disabled')).toBe('true');
    expect(button('Pause').getAttribute('title')).toMatch(/reconnecting/);
    expect(button('Stop').getAttribute('aria-disabled')).toBeNull();
  });
});
