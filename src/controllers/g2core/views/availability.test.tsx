// @vitest-environment happy-dom
import { act, cleanup, render, screen } from '@testing-library/react';
import { afterEach, describe, expect, it } from 'vitest';
import { createContext } from '../../../fleet/fleet';
import { alwaysVisible } from '../../../fleet/link';
import { G2coreSession } from '../session';
import { job } from '../wire';
import { WhyNot } from './common';

afterEach(cleanup);

/**
 * Issue 12, defect 3 for g2core: what a command's availability reads is in the stores the
 * command names (the snapshot and the family's `detail`), and what is on screen follows a
 * change of the family store alone. The session is never started: no request is made.
 */
function makeSession(): G2coreSession {
  const ctx = createContext(
    { id: 'cnc', name: 'CNC', kind: 'g2core', simulated: true },
    { visibility: alwaysVisible, principal: () => ({ name: 'sam', role: 'supervisor' }) },
  );
  ctx.snapshot.setState({ link: 'online', activity: 'idle' });
  return new G2coreSession(ctx);
}

const running = job.parse({ id: 3, name: 'part.nc', state: 'running', lines: 10, done: 2 });

describe('g2core command availability follows the family store', () => {
  it('every command names the snapshot and the family store', () => {
    const s = makeSession();
    for (const cmd of Object.values(s.commands)) expect(cmd.needs).toEqual([s.ctx.snapshot, s.detail]);
  });

  it('MDI: a job appearing in the family store alone blocks it on screen, and its end frees it', () => {
    const s = makeSession();
    s.detail.setState({ sr: { stat: 1 } });
    render(<WhyNot session={s} command={s.mdi} />);
    const why = () => screen.queryByTestId('g2-whynot-g2core.mdi')?.textContent ?? null;
    expect(why()).toBeNull();
    const snapshot = s.ctx.snapshot.getState();
    act(() => s.detail.setState({ jobs: [running] }));
    expect(s.ctx.snapshot.getState()).toBe(snapshot); // the snapshot did not change
    expect(why()).toMatch(/Not while job "part.nc" runs/);
    expect(s.ctx.commands.blockedReason(s.mdi)).toBe(why()); // the runner agrees with the screen
    act(() => s.detail.setState({ jobs: [] }));
    expect(why()).toBeNull();
    expect(s.ctx.commands.blockedReason(s.mdi)).toBeNull();
  });

  it('Feedhold: the server refusing GET /operation (a family-store flag) changes the reason on screen', () => {
    const s = makeSession();
    // Something moves that this console did not start.
    s.detail.setState({ sr: { stat: 5 } });
    render(<WhyNot session={s} command={s.feedhold} />);
    const why = () => screen.queryByTestId('g2-whynot-g2core.feedhold')?.textContent ?? null;
    expect(why()).toMatch(/Looking for the operation/);
    act(() => s.detail.setState({ opsList: false }));
    expect(why()).toMatch(/cannot list its operations/);
    expect(s.opsListSupported).toBe(false);
    act(() => s.detail.setState({ jobs: [running] })); // a job: Feedhold acts on it
    expect(why()).toBeNull();
    expect(s.ctx.commands.blockedReason(s.feedhold)).toBeNull();
  });
});
