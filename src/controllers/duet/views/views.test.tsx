// @vitest-environment happy-dom
import { act, cleanup, fireEvent, render, screen, waitFor } from '@testing-library/react';
import { setupServer } from 'msw/node';
import { afterAll, afterEach, beforeAll, beforeEach, describe, expect, it } from 'vitest';
import { createContext } from '../../../fleet/fleet';
import { alwaysVisible } from '../../../fleet/link';
import { simulatorHandlers } from '../../../fleet/msw';
import { CommandButton } from '../../../fleet/react';
import { DuetSession } from '../session';
import { DuetSimulator } from '../sim/simulator';
import { Files } from './Files';
import { Overview } from './Overview';

let sim: DuetSimulator;
let session: DuetSession;
const server = setupServer();

beforeAll(() => server.listen({ onUnhandledRequest: 'error' }));
afterAll(() => server.close());
beforeEach(async () => {
  sim = new DuetSimulator({ id: 'dv', name: 'duet-sim', tickMs: 100 });
  server.resetHandlers(...simulatorHandlers('dv', sim));
  const ctx = createContext(
    { id: 'dv', name: 'Duet', kind: 'duet', simulated: true },
    { visibility: alwaysVisible, principal: () => ({ name: 't', role: 'operator' }) },
  );
  session = new DuetSession(ctx);
  session.start();
  await waitFor(() => expect(ctx.snapshot.getState().link).toBe('online'), { timeout: 5000 });
});
afterEach(() => {
  cleanup();
  session.stop();
  sim.dispose();
});

describe('Duet views', () => {
  it('overview: status, a running job, pause without confirmation, then resume and stop job offered', async () => {
    // The machine page: the family's job commands (shown by the page's shared job control row,
    // src/app/kiosk/JobControls.tsx, which a family may not import) over the family's overview.
    const { commands: runner, snapshot } = session.ctx;
    const c = session.cmd;
    render(
      <>
        {[c.pause, c.resume, c.cancel, c.estop].map((cmd) => (
          <CommandButton key={cmd.id} runner={runner} snapshot={snapshot} command={cmd} args={undefined} />
        ))}
        <Overview session={session} />
      </>,
    );
    expect(screen.getByTestId('duet-status').textContent).toBe('Idle');
    expect(screen.getByTestId('duet-board').textContent).toContain('Simulated Duet 3 Mini 5+');
    expect(screen.getByTestId('cmd-duet.estop')).toBeTruthy();
    act(() => void sim.runCode('M32 "0:/gcodes/bracket.gcode"'));
    await waitFor(() => expect(screen.getByTestId('duet-job-name').textContent).toBe('bracket.gcode'), {
      timeout: 3000,
    });
    await waitFor(() =>
      expect(screen.getByTestId('cmd-duet.pause').getAttribute('aria-disabled')).toBeNull(),
    );
    expect(screen.getByTestId('cmd-duet.cancel').getAttribute('aria-disabled')).toBe('true');
    fireEvent.click(screen.getByTestId('cmd-duet.pause'));
    await waitFor(
      () => expect(screen.getByTestId('cmd-duet.cancel').getAttribute('aria-disabled')).toBeNull(),
      {
        timeout: 3000,
      },
    );
    expect(sim.codes).toContain('M25');
    expect(screen.getByTestId('cmd-duet.resume').getAttribute('aria-disabled')).toBeNull();
  });

  it('answers a choice message box with M292 R{index}', async () => {
    render(<Overview session={session} />);
    act(() => void sim.raiseMessageBox(4));
    await screen.findByTestId('duet-messagebox', undefined, { timeout: 3000 });
    fireEvent.click(screen.getByTestId('duet-choice-2'));
    fireEvent.click(screen.getByTestId('duet-messagebox-ok'));
    await waitFor(() => expect(sim.answers.at(-1)?.value).toBe('2'));
    await waitFor(() => expect(screen.queryByTestId('duet-messagebox')).toBeNull());
  });

  it('a message box can be put off and opened again; the emergency stop stays reachable', async () => {
    render(<Overview session={session} />);
    act(() => void sim.raiseMessageBox(3));
    await screen.findByTestId('duet-messagebox', undefined, { timeout: 3000 });
    expect(screen.getByTestId('duet-messagebox-estop')).toBeTruthy();
    fireEvent.click(screen.getByTestId('duet-messagebox-hide'));
    expect(screen.queryByTestId('duet-messagebox')).toBeNull();
    fireEvent.click(screen.getByTestId('duet-messagebox-reopen'));
    expect(screen.getByTestId('duet-messagebox')).toBeTruthy();
    fireEvent.click(screen.getByTestId('duet-messagebox-cancel'));
    await waitFor(() => expect(sim.answers.at(-1)).toMatchObject({ cancelled: true }));
  });

  it('refuses an integer outside min/max before sending', async () => {
    render(<Overview session={session} />);
    act(() => void sim.raiseMessageBox(5));
    const input = (await screen.findByTestId('duet-messagebox-input', undefined, {
      timeout: 3000,
    })) as HTMLInputElement;
    fireEvent.change(input, { target: { value: '99' } });
    expect(screen.getByRole('alert').textContent).toMatch(/At most 10/);
    fireEvent.change(input, { target: { value: '4' } });
    fireEvent.click(screen.getByTestId('duet-messagebox-ok'));
    await waitFor(() => expect(sim.answers.at(-1)?.value).toBe('4'));
  });

  it('files: lists the jobs folder with thumbnails', async () => {
    render(<Files session={session} />);
    await waitFor(() => expect(screen.getAllByTestId('duet-file-row').length).toBe(3), { timeout: 3000 });
    const names = screen.getAllByTestId('duet-file-row').map((r) => r.getAttribute('data-name'));
    expect(names).toEqual(['enclosure', 'bracket.gcode', 'gear.gcode']);
    await waitFor(() => expect(document.querySelector('img[data-format="png"]')).toBeTruthy(), {
      timeout: 3000,
    });
    expect(document.querySelector('img[data-format="jpeg"]')).toBeTruthy();
  });
});
