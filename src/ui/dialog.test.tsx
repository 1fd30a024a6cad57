// @vitest-environment happy-dom
import { act, cleanup, fireEvent, render, screen } from '@testing-library/react';
import { useState } from 'react';
import { afterEach, describe, expect, it, vi } from 'vitest';
import { Button, Dialog, STOP_CONTROLS } from './components';

/** Dialog on the native <dialog>: focus once on open, never on a stop control, back on close. */

afterEach(() => {
  cleanup();
  vi.restoreAllMocks();
});

function Harness(props: {
  onCancel?: () => void;
  dismissible?: boolean;
  stopFirst?: boolean;
  autofocusCancel?: boolean;
}) {
  const [open, setOpen] = useState(false);
  const [tick, setTick] = useState(0);
  const close = () => {
    props.onCancel?.();
    setOpen(false);
  };
  return (
    <>
      <button type="button" onClick={() => setOpen(true)}>
        Open
      </button>
      <button type="button" onClick={() => setTick((t) => t + 1)}>
        Tick
      </button>
      {open && (
        <Dialog
          title={`Question ${tick}`}
          // A new function each render, as most owners pass.
          onCancel={() => close()}
          dismissible={props.dismissible}
          role="alertdialog"
          testId="dlg"
          actions={
            <>
              {props.stopFirst && (
                <Button data-stop variant="danger">
                  Emergency stop
                </Button>
              )}
              <Button onClick={close} data-autofocus={props.autofocusCancel || undefined}>
                Cancel
              </Button>
              <Button variant="danger">Yes</Button>
            </>
          }
        >
          <p>Really?</p>
        </Dialog>
      )}
    </>
  );
}

function openIt(): HTMLDialogElement {
  const opener = screen.getByRole('button', { name: 'Open' });
  act(() => opener.focus());
  fireEvent.click(opener);
  return screen.getByTestId('dlg') as HTMLDialogElement;
}

describe('Dialog', () => {
  it('is a native modal <dialog> named by its heading, with the alertdialog role when asked', () => {
    const showModal = vi.spyOn(HTMLDialogElement.prototype, 'showModal');
    render(<Harness />);
    const dlg = openIt();
    expect(dlg.tagName).toBe('DIALOG');
    expect(showModal).toHaveBeenCalledTimes(1);
    expect(dlg.open).toBe(true);
    expect(screen.getByRole('alertdialog', { name: 'Question 0' })).toBe(dlg);
  });

  it('falls back to the open attribute where showModal is missing', () => {
    const proto = HTMLDialogElement.prototype as { showModal?: unknown };
    const original = proto.showModal;
    proto.showModal = undefined;
    try {
      render(<Harness />);
      expect(openIt().hasAttribute('open')).toBe(true);
    } finally {
      proto.showModal = original;
    }
  });

  it('focuses [data-autofocus] once; re-renders leave focus where the user put it', () => {
    render(<Harness autofocusCancel />);
    const dlg = openIt();
    expect(document.activeElement).toBe(screen.getByRole('button', { name: 'Cancel' }));
    const yes = screen.getByRole('button', { name: 'Yes' });
    act(() => yes.focus());
    // A re-render of the owner (a new title, a new onCancel): focus stays.
    fireEvent.click(screen.getByRole('button', { name: 'Tick', hidden: true }));
    expect(dlg.textContent).toContain('Question 1');
    expect(document.activeElement).toBe(yes);
  });

  it('never focuses a stop control by itself, even when it is the first control', () => {
    render(<Harness stopFirst />);
    openIt();
    const active = document.activeElement;
    expect(active?.matches(STOP_CONTROLS)).toBe(false);
    expect(active).toBe(screen.getByRole('button', { name: 'Cancel' }));
  });

  it('the cancel event (Escape) cancels once and is prevented; focus goes back to the opener', async () => {
    const onCancel = vi.fn();
    render(<Harness onCancel={onCancel} />);
    const dlg = openIt();
    const ev = new Event('cancel', { cancelable: true });
    act(() => {
      dlg.dispatchEvent(ev);
    });
    expect(ev.defaultPrevented).toBe(true);
    expect(onCancel).toHaveBeenCalledTimes(1);
    expect(screen.queryByTestId('dlg')).toBeNull();
    await act(() => Promise.resolve());
    expect(document.activeElement).toBe(screen.getByRole('button', { name: 'Open' }));
  });

  it('Escape cancels where the DOM sends no cancel event', async () => {
    const onCancel = vi.fn();
    render(<Harness onCancel={onCancel} />);
    openIt();
    fireEvent.keyDown(screen.getByRole('button', { name: 'Cancel' }), { key: 'Escape' });
    await act(() => new Promise((r) => setTimeout(r, 5)));
    expect(onCancel).toHaveBeenCalledTimes(1);
    expect(screen.queryByTestId('dlg')).toBeNull();
  });

  it('a dialog that is not dismissible ignores Escape', async () => {
    const onCancel = vi.fn();
    render(<Harness onCancel={onCancel} dismissible={false} />);
    const dlg = openIt();
    act(() => {
      dlg.dispatchEvent(new Event('cancel', { cancelable: true }));
    });
    fireEvent.keyDown(dlg, { key: 'Escape' });
    await act(() => new Promise((r) => setTimeout(r, 5)));
    expect(onCancel).not.toHaveBeenCalled();
    expect(screen.getByTestId('dlg')).toBeTruthy();
  });

  it('under an inert page it opens in place, and becomes modal when the page is live again', async () => {
    const showModal = vi.spyOn(HTMLDialogElement.prototype, 'showModal');
    const onCancel = vi.fn();
    const { container } = render(
      <div data-testid="page" inert>
        <Dialog title="Box" onCancel={onCancel} testId="box" actions={<Button>OK</Button>}>
          <p>From the machine</p>
        </Dialog>
      </div>,
    );
    const box = screen.getByTestId('box') as HTMLDialogElement;
    expect(box.hasAttribute('open')).toBe(true);
    expect(showModal).not.toHaveBeenCalled();
    act(() => container.querySelector('[data-testid="page"]')?.removeAttribute('inert'));
    await act(() => new Promise((r) => setTimeout(r, 0)));
    expect(showModal).toHaveBeenCalledTimes(1);
    expect(box.open).toBe(true);
    expect(document.activeElement).toBe(screen.getByRole('button', { name: 'OK' }));
    // Its own close on the way to modal is no cancel.
    await act(() => new Promise((r) => setTimeout(r, 5)));
    expect(onCancel).not.toHaveBeenCalled();
  });

  it('a dialog that is not dismissible opens again when the browser closes it anyway', () => {
    render(<Harness dismissible={false} />);
    const dlg = openIt();
    act(() => dlg.close());
    expect(dlg.open).toBe(true);
  });
});
