// @vitest-environment happy-dom
import { act, cleanup, render, screen } from '@testing-library/react';
import { afterEach, describe, expect, it } from 'vitest';
import { useStore } from 'zustand';
import type { CommandDecl } from '../../../fleet/commands';
import { createContext } from '../../../fleet/fleet';
import { useBlockedReason } from '../../../fleet/kernel';
import { alwaysVisible } from '../../../fleet/link';
import { memoryDraftStorage } from '../../../forms/storage';
import { PruntSession } from '../session';

afterEach(cleanup);

function setup() {
  const ctx = createContext(
    { id: 'pa', name: 'Printer', kind: 'prunt', simulated: true },
    { visibility: alwaysVisible, principal: () => ({ name: 't', role: 'supervisor' }) },
  );
  ctx.snapshot.setState({ link: 'online', activity: 'idle' });
  const session = new PruntSession(ctx, { drafts: memoryDraftStorage() });
  function Reason<A>(props: { command: CommandDecl<A>; testId: string }) {
    const reason = useBlockedReason(ctx.commands, ctx.snapshot, props.command);
    return <p data-testid={props.testId}>{reason ?? 'available'}</p>;
  }
  return { ctx, session, Reason };
}

/**
 * Issue 12, defect 3, for Prunt: what a button says follows every store its command's
 * availability reads — here the Prunt store alone (the startup state), with no snapshot change.
 */
describe('Prunt command availability on screen', () => {
  it('follows a Prunt-store change alone: firmware permission and "Run file" by startup state', () => {
    const { ctx, session, Reason } = setup();
    render(
      <>
        <Reason command={session.cmd.allowFirmwareUpdate} testId="allow" />
        <Reason command={session.cmd.runFile} testId="run" />
      </>,
    );
    const text = (id: string) => screen.getByTestId(id).textContent;
    expect(text('allow')).toBe('No firmware update is required');
    expect(text('run')).toBe('available');
    const snap = ctx.snapshot.getState();
    act(() => session.store.setState({ startup: 'Update_Required' }));
    expect(ctx.snapshot.getState()).toBe(snap); // only the family store changed
    expect(text('allow')).toBe('available');
    expect(text('run')).toBe('The server is not ready (Update_Required)');
    act(() => session.store.setState({ startup: 'Done' }));
    expect(text('allow')).toBe('No firmware update is required');
    expect(text('run')).toBe('available');
  });

  it('a tick with equal values keeps their identity: a view of them does not re-render', () => {
    const { session } = setup();
    let renders = 0;
    function X() {
      renders++;
      const x = useStore(session.store, (s) => s.status['M']?.['G']);
      return <p>{String(x?.['x'])}</p>;
    }
    render(<X />);
    act(() => session.store.setState({ status: { M: { G: { x: 1 }, H: { y: 1 } } }, statusAt: 1 }));
    expect(renders).toBe(2);
    // New objects, equal values in M.G (only H changed): the view keeps its data and is not rendered.
    act(() => session.store.setState({ status: { M: { G: { x: 1 }, H: { y: 2 } } }, statusAt: 2 }));
    expect(renders).toBe(2);
    act(() => session.store.setState({ status: { M: { G: { x: 2 }, H: { y: 2 } } }, statusAt: 3 }));
    expect(renders).toBe(3);
  });
});
