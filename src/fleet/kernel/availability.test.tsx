// @vitest-environment happy-dom
import { act, cleanup, render, screen } from '@testing-library/react';
import { afterEach, describe, expect, it } from 'vitest';
import { createStore } from 'zustand/vanilla';
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
