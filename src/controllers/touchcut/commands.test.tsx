// @vitest-environment happy-dom
import { act, cleanup, render, screen } from '@testing-library/react';
import { afterEach, describe, expect, it } from 'vitest';
import { createContext } from '../../fleet/fleet';
import { useBlockedReason } from '../../fleet/kernel';
import { alwaysVisible } from '../../fleet/link';
import { TouchcutSession } from './session';
import { KEY_AUTH } from './state';

afterEach(cleanup);

function session(): TouchcutSession {
  const ctx = createContext(
    { id: 'tcc', name: 'Plasma', kind: 'touchcut', simulated: true },
    { visibility: alwaysVisible, principal: () => ({ name: 'sam', role: 'operator' }) },
  );
  ctx.snapshot.setState({ link: 'online', activity: 'idle' });
  return new TouchcutSession(ctx);
}

/** What a command button shows: subscribed to exactly the stores the command's availability names. */
function PasswordButton({ session: s }: { session: TouchcutSession }) {
  const reason = useBlockedReason(s.ctx.commands, s.ctx.snapshot, s.changePassword);
  return (
    <button type="button" aria-disabled={reason ? true : undefined} title={reason ?? undefined}>
      {s.changePassword.label}
    </button>
  );
}

describe('touchcut commands', () => {
  it('keeps the command id of the audit log and the access rules', () => {
    const s = session();
    expect(Object.keys(s.commands)).toEqual(['touchcut.changePassword']);
    expect(s.commands['touchcut.changePassword']).toBe(s.changePassword);
    expect(s.changePassword).toMatchObject({ hazard: 'adjust', role: 'operator', confirm: false });
  });

  it('change password follows the session store alone: a login makes it available, key access not', () => {
    const s = session();
    const { ctx } = s;
    expect(s.changePassword.needs).toEqual([ctx.snapshot, s.store]);
    render(<PasswordButton session={s} />);
    const button = () => screen.getByRole('button', { name: 'Change TouchCut password' });
    expect(button().getAttribute('aria-disabled')).toBe('true');
    expect(button().getAttribute('title')).toMatch(/user login/);

    const snapshot = ctx.snapshot.getState();
    act(() => s.store.setState({ auth: { mode: 'user', user: 'admin', expiresAt: null, reason: null } }));
    expect(ctx.snapshot.getState()).toBe(snapshot); // only the family store changed
    expect(ctx.commands.blockedReason(s.changePassword)).toBeNull();
    expect(button().getAttribute('aria-disabled')).toBeNull();

    act(() => s.store.setState({ auth: KEY_AUTH }));
    expect(ctx.commands.blockedReason(s.changePassword)).toMatch(/user login/);
    expect(button().getAttribute('aria-disabled')).toBe('true');
  });
});
