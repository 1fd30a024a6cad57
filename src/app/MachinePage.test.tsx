// @vitest-environment happy-dom
import { cleanup, fireEvent, render, screen } from '@testing-library/react';
import { useState } from 'react';
import { afterEach, beforeAll, describe, expect, it } from 'vitest';
import { registerController } from '../controllers';
import type { ControllerModule, MachineSession, SessionContext, TabProps } from '../fleet/contract';
import { createRuntime, fleetStore, registerRuntime } from '../fleet/fleet';
import { alwaysVisible } from '../fleet/link';
import type { MachineInfo } from '../fleet/types';
import { MachinePage } from './MachinePage';

/** A tab with state of its own: the file picked, as a family's Files tab keeps it. */
function Picker({ session }: TabProps<MachineSession>) {
  const [picked, setPicked] = useState<string | null>(null);
  return (
    <p>
      <button onClick={() => setPicked(`part of ${session.machine.id}`)}>Pick</button>
      <span data-testid="picked">{picked ?? 'nothing picked'}</span>
    </p>
  );
}

const mod: ControllerModule = {
  kind: 'prunt',
  label: 'Fake printer',
  createSession: (ctx: SessionContext): MachineSession => ({
    machine: ctx.machine,
    ctx,
    commands: {},
    start: () => undefined,
    stop: () => undefined,
  }),
  tabs: [{ id: 'overview', label: 'Overview', Component: Picker }],
};

const A: MachineInfo = { id: 'a', name: 'Printer A', kind: 'prunt', simulated: false };
const B: MachineInfo = { id: 'b', name: 'Printer B', kind: 'prunt', simulated: false };

beforeAll(() => {
  registerController(mod);
  for (const info of [A, B]) {
    const rt = createRuntime(info, (c) => mod.createSession(c), { visibility: alwaysVisible });
    registerRuntime(rt);
  }
  fleetStore.setState({ status: 'ready', machines: [A, B], error: null });
});

afterEach(cleanup);

describe('the machine page', () => {
  it("shown for another machine (/m/a, then /m/b) starts afresh: nothing of A's page state is B's", () => {
    const { rerender } = render(<MachinePage id="a" tab={null} />);
    fireEvent.click(screen.getByRole('button', { name: 'Pick' }));
    expect(screen.getByTestId('picked').textContent).toBe('part of a');
    rerender(<MachinePage id="b" tab={null} />);
    expect(screen.getByTestId('machine-b')).toBeTruthy();
    expect(screen.getByTestId('picked').textContent).toBe('nothing picked');
  });
});
