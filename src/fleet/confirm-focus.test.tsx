// @vitest-environment happy-dom
import { act, cleanup, fireEvent, render, screen, within } from '@testing-library/react';
import { afterEach, describe, expect, it } from 'vitest';
import type { CommandDecl } from './commands';
import { createContext } from './fleet';
import { alwaysVisible } from './link';
import { CommandButton } from './react';

/**
 * Issue 12, defect 2: every confirmation dialog moved focus back to Cancel on any re-render
 * (`Yes, kill` focused → a status update → Enter cancels). Focus is set on Cancel once, when the
 * confirmation opens; after that it stays where the user puts it.
 */

afterEach(cleanup);

function setup(extra: Partial<CommandDecl> = {}) {
  const ctx = createContext(
    { id: 'm1', name: 'M1', kind: 'g2core', simulated: true },
    { visibility: alwaysVisible, principal: () => ({ name: 'op', role: 'operator' }) },
  );
  ctx.snapshot.setState({ link: 'online', activity: 'running', activityLabel: 'Running line 120' });
  const sent: string[] = [];
  const kill: CommandDecl = {
    id: 'test.kill',
    label: 'Kill',
    hazard: 'stop',
    role: 'operator',
    confirm: 'Kill: stop motion now and abandon the job?',
    perform: async () => {
      sent.push('kill');
      return 'killed';
    },
    ...extra,
  };
  render(
    <>
      <button type="button">elsewhere</button>
      <CommandButton runner={ctx.commands} snapshot={ctx.snapshot} command={kill} args={undefined} />
    </>,
  );
  return { ctx, sent };
}

/** A status update of the kind that arrives several times a second while a job runs. */
function statusUpdate(ctx: ReturnType<typeof setup>['ctx'], line: number): void {
  act(() => ctx.snapshot.setState({ activityLabel: `Running line ${line}`, updatedAt: Date.now() }));
}

describe('confirmation focus (issue 12, defect 2)', () => {
  it('opens with focus on the dismiss ("Keep running"), then leaves focus on "Yes, kill" through status updates', () => {
    const { ctx, sent } = setup();
    const trigger = screen.getByRole('button', { name: 'Kill' });
    act(() => trigger.focus());
    fireEvent.click(trigger);
    const dialog = screen.getByTestId('confirm-dialog');
    const cancel = within(dialog).getByRole('button', { name: 'Keep running' });
    const yes = within(dialog).getByRole('button', { name: 'Yes, kill' });
    expect(document.activeElement).toBe(cancel);

    act(() => yes.focus());
    for (let line = 121; line < 125; line++) statusUpdate(ctx, line);
    expect(document.activeElement).toBe(yes);
    expect(sent).toEqual([]);
  });

  it('a status update with the dismiss focused leaves it there (and nothing is sent)', () => {
    const { ctx, sent } = setup();
    fireEvent.click(screen.getByRole('button', { name: 'Kill' }));
    const dialog = screen.getByTestId('confirm-dialog');
    const cancel = within(dialog).getByRole('button', { name: 'Keep running' });
    statusUpdate(ctx, 121);
    expect(document.activeElement).toBe(cancel);
    expect(sent).toEqual([]);
  });

  it('a two-step confirmation puts focus on the dismiss ("Go back") again for the second question, once', () => {
    const { ctx } = setup({ confirmTwice: true, hazard: 'dangerous', label: 'Upgrade firmware' });
    fireEvent.click(screen.getByRole('button', { name: 'Upgrade firmware' }));
    fireEvent.click(within(screen.getByTestId('confirm-dialog')).getByRole('button', { name: 'Continue' }));
    const dialog = screen.getByTestId('confirm-dialog');
    expect(dialog.textContent).toContain('second confirmation');
    expect(document.activeElement).toBe(within(dialog).getByRole('button', { name: 'Go back' }));
    const yes = within(dialog).getByRole('button', { name: 'Yes, upgrade firmware' });
    act(() => yes.focus());
    statusUpdate(ctx, 130);
    expect(document.activeElement).toBe(yes);
  });
});
