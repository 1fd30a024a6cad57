// @vitest-environment happy-dom
import { act, cleanup, render, screen, waitFor, within } from '@testing-library/react';
import { setupServer } from 'msw/node';
import { afterAll, afterEach, beforeAll, beforeEach, describe, expect, it } from 'vitest';
import { createContext } from '../../../fleet/fleet';
import { alwaysVisible } from '../../../fleet/link';
import { simulatorHandlers } from '../../../fleet/msw';
import { STOP_CONTROLS } from '../../../ui';
import { DuetSession } from '../session';
import { DuetSimulator } from '../sim/simulator';
import { DuetFrame } from './common';

/**
 * Issue 12, defect 1: with a message box open, the next model frame re-ran the dialog's focus
 * effect and put focus on Emergency stop (the first button in the dialog); Enter then sent
 * M112 + M999. Focus is set once when the box opens, never on a stop control, and stays where
 * the user put it while frames arrive.
 */

let sim: DuetSimulator;
let session: DuetSession;
const server = setupServer();

beforeAll(() => server.listen({ onUnhandledRequest: 'error' }));
afterAll(() => server.close());
beforeEach(async () => {
  sim = new DuetSimulator({ id: 'dfocus', name: 'duet-sim', tickMs: 50 });
  server.resetHandlers(...simulatorHandlers('dfocus', sim));
  const ctx = createContext(
    { id: 'dfocus', name: 'Duet', kind: 'duet', simulated: true },
    { visibility: alwaysVisible, principal: () => ({ name: 't', role: 'supervisor' }) },
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

/** Resolves after `n` more object-model frames reached the session's store (and React). */
async function modelFrames(n: number): Promise<void> {
  const first = session.store.getState().model;
  let seen = 0;
  let last = first;
  await waitFor(
    () => {
      const m = session.store.getState().model;
      if (m !== last) {
        seen++;
        last = m;
      }
      expect(seen).toBeGreaterThanOrEqual(n);
    },
    { timeout: 5000, interval: 20 },
  );
}

function active(): Element | null {
  return document.activeElement;
}

function describeEl(el: Element | null): string {
  if (!el) return 'nothing';
  return `${el.tagName.toLowerCase()}[data-testid=${el.getAttribute('data-testid')}] "${el.textContent ?? ''}"`;
}

describe('Duet message box focus (issue 12, defect 1)', () => {
  it.each([0, 1, 2, 3, 4, 5, 6, 7])(
    'mode %i: focus moves into the box once, never onto Emergency stop, and stays put while model frames arrive',
    async (mode) => {
      render(
        <DuetFrame session={session}>
          <button type="button">page content</button>
        </DuetFrame>,
      );
      act(() => void sim.raiseMessageBox(mode, mode === 2 ? { axisControls: 0b111 } : {}));
      const dialog = await screen.findByTestId('duet-messagebox', undefined, { timeout: 3000 });
      const estop = within(dialog).getByRole('button', { name: 'Emergency stop' });

      // On open: inside the box, not on a stop control.
      const opened = active();
      expect(dialog.contains(opened), `focus on open: ${describeEl(opened)}`).toBe(true);
      expect(opened, 'focus on open is Emergency stop').not.toBe(estop);
      expect(opened?.matches(STOP_CONTROLS), `focus on open: ${describeEl(opened)}`).toBe(false);

      // Frames arrive: focus stays on what had it.
      await modelFrames(3);
      expect(active(), `after frames: ${describeEl(active())}`).toBe(opened);

      // The user moves to another control of the box; more frames: focus stays there.
      const target =
        within(dialog).queryByTestId('duet-messagebox-ok') ??
        within(dialog).getByTestId('duet-messagebox-hide');
      act(() => target.focus());
      expect(active()).toBe(target);
      await modelFrames(3);
      expect(active(), `after frames: ${describeEl(active())}`).toBe(target);
      expect(sim.codes.some((c) => /M112/.test(c))).toBe(false);
    },
  );
});
