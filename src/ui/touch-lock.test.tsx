// @vitest-environment happy-dom
import { act, cleanup, fireEvent, render, screen } from '@testing-library/react';
import { afterEach, beforeEach, describe, expect, it, vi } from 'vitest';
import { LockableInput, LockableSlider, TouchLockPolicy, type TouchLockMode } from './Lockable';
import { createTouchLock, RELOCK_AFTER_MS } from './touch-lock';

beforeEach(() => {
  vi.useFakeTimers();
});
afterEach(() => {
  cleanup();
  vi.useRealTimers();
});

describe('createTouchLock', () => {
  it('starts locked, unlocks on request and locks again after the delay without use', () => {
    const lock = createTouchLock(5000);
    const seen: boolean[] = [];
    lock.subscribe(() => seen.push(lock.locked));
    expect(lock.locked).toBe(true);
    lock.unlock();
    expect(lock.locked).toBe(false);
    vi.advanceTimersByTime(4999);
    expect(lock.locked).toBe(false);
    vi.advanceTimersByTime(1);
    expect(lock.locked).toBe(true);
    expect(seen).toEqual([false, true]);
  });

  it('each use while unlocked starts the countdown again', () => {
    const lock = createTouchLock(5000);
    lock.unlock();
    vi.advanceTimersByTime(4000);
    lock.touch();
    vi.advanceTimersByTime(4000);
    expect(lock.locked).toBe(false);
    vi.advanceTimersByTime(1000);
    expect(lock.locked).toBe(true);
  });

  it('a touch while locked does not unlock it, nor start a countdown', () => {
    const lock = createTouchLock(5000);
    lock.touch();
    expect(lock.locked).toBe(true);
    expect(vi.getTimerCount()).toBe(0);
  });

  it('locking by hand stops the countdown; no delay means it stays unlocked', () => {
    const lock = createTouchLock(5000);
    lock.unlock();
    lock.lock();
    expect(lock.locked).toBe(true);
    expect(vi.getTimerCount()).toBe(0);
    const open = createTouchLock(null);
    open.unlock();
    vi.advanceTimersByTime(RELOCK_AFTER_MS * 10);
    expect(open.locked).toBe(false);
  });

  it('dispose stops the countdown and locks', () => {
    const lock = createTouchLock(5000);
    lock.unlock();
    lock.dispose();
    expect(vi.getTimerCount()).toBe(0);
    expect(lock.locked).toBe(true);
  });
});

function renderSlider(mode: TouchLockMode, onCommit = vi.fn()) {
  render(
    <TouchLockPolicy value={mode}>
      <LockableSlider
        label="Feed override"
        value={100}
        min={5}
        max={200}
        step={5}
        format={(v) => `${v} %`}
        onCommit={onCommit}
        testId="feed"
      />
    </TouchLockPolicy>,
  );
  return { onCommit, slider: screen.getByRole('slider', { name: 'Feed override' }) as HTMLInputElement };
}

/** A drag as the browser reports it: input events while it moves, `change` when it ends. */
function drag(slider: HTMLInputElement, to: number) {
  fireEvent.input(slider, { target: { value: String(to) } });
  slider.dispatchEvent(new Event('change', { bubbles: true }));
}

describe('LockableSlider', () => {
  it('locked, it is disabled and a drag changes nothing; unlocked, the value is sent once', async () => {
    const { onCommit, slider } = renderSlider('always');
    expect(slider.disabled).toBe(true);
    expect(screen.getByTestId('feed').dataset.locked).toBe('true');
    drag(slider, 150);
    expect(onCommit).not.toHaveBeenCalled();
    expect(screen.getByTestId('feed-value').textContent).toBe('100 %');

    fireEvent.click(screen.getByRole('button', { name: 'Unlock Feed override' }));
    expect(slider.disabled).toBe(false);
    drag(slider, 150);
    await act(async () => {
      await vi.advanceTimersByTimeAsync(0);
    });
    expect(onCommit).toHaveBeenCalledTimes(1);
    expect(onCommit).toHaveBeenCalledWith(150);
  });

  it('locks again by itself after the relock delay without use', () => {
    const { slider } = renderSlider('always');
    fireEvent.click(screen.getByRole('button', { name: 'Unlock Feed override' }));
    expect(slider.disabled).toBe(false);
    act(() => {
      vi.advanceTimersByTime(RELOCK_AFTER_MS);
    });
    expect(slider.disabled).toBe(true);
    expect(screen.getByRole('button', { name: 'Unlock Feed override' })).toBeTruthy();
  });

  it('the lock button locks it again at once', () => {
    const { slider } = renderSlider('always');
    fireEvent.click(screen.getByRole('button', { name: 'Unlock Feed override' }));
    fireEvent.click(screen.getByRole('button', { name: 'Lock Feed override' }));
    expect(slider.disabled).toBe(true);
  });

  it('with a fine pointer (auto, no touch screen) it has no lock and works at once', async () => {
    const { onCommit, slider } = renderSlider('auto');
    expect(screen.queryByRole('button', { name: /lock/i })).toBeNull();
    expect(slider.disabled).toBe(false);
    drag(slider, 50);
    await act(async () => {
      await vi.advanceTimersByTimeAsync(0);
    });
    expect(onCommit).toHaveBeenCalledWith(50);
  });

  it('on a touch screen (pointer: coarse) auto locks it', () => {
    const spy = vi.spyOn(window, 'matchMedia').mockImplementation(
      (q: string) =>
        ({
          matches: q === '(pointer: coarse)',
          media: q,
          addEventListener: () => undefined,
          removeEventListener: () => undefined,
        }) as unknown as MediaQueryList,
    );
    try {
      const { slider } = renderSlider('auto');
      expect(slider.disabled).toBe(true);
      expect(screen.getByRole('button', { name: 'Unlock Feed override' })).toBeTruthy();
    } finally {
      spy.mockRestore();
    }
  });
});

describe('LockableSlider after a value was sent', () => {
  function Slider(props: { value: number; onCommit: (v: number) => Promise<boolean> }) {
    return (
      <TouchLockPolicy value="never">
        <LockableSlider
          label="Feed"
          value={props.value}
          min={5}
          max={200}
          step={5}
          onCommit={props.onCommit}
          testId="f"
        />
      </TouchLockPolicy>
    );
  }

  it('shows the value sent until the controller answers with its own', async () => {
    const { rerender } = render(<Slider value={100} onCommit={() => Promise.resolve(true)} />);
    drag(screen.getByRole('slider') as HTMLInputElement, 150);
    await act(async () => {
      await vi.advanceTimersByTimeAsync(0);
    });
    // Not the old 100 while the controller's read is on its way.
    expect(screen.getByTestId('f-value').textContent).toBe('150');
    rerender(<Slider value={145} onCommit={() => Promise.resolve(true)} />);
    expect(screen.getByTestId('f-value').textContent).toBe('145');
  });

  it('shows the old value again when it was not set, or when no answer changes it', async () => {
    const { rerender } = render(<Slider value={100} onCommit={() => Promise.resolve(false)} />);
    drag(screen.getByRole('slider') as HTMLInputElement, 150);
    await act(async () => {
      await vi.advanceTimersByTimeAsync(0);
    });
    expect(screen.getByTestId('f-value').textContent).toBe('100');

    rerender(<Slider value={100} onCommit={() => Promise.resolve(true)} />);
    drag(screen.getByRole('slider') as HTMLInputElement, 150);
    await act(async () => {
      await vi.advanceTimersByTimeAsync(0);
    });
    expect(screen.getByTestId('f-value').textContent).toBe('150');
    await act(async () => {
      await vi.advanceTimersByTimeAsync(5000);
    });
    expect(screen.getByTestId('f-value').textContent).toBe('100');
  });
});

describe('LockableInput', () => {
  it('is read-only while locked and ignores typing; unlocked it passes changes on', () => {
    const onChange = vi.fn();
    render(
      <TouchLockPolicy value="always">
        <LockableInput aria-label="Tilt threshold" lockLabel="tilt threshold" value="" onChange={onChange} />
      </TouchLockPolicy>,
    );
    const input = screen.getByRole('textbox', { name: 'Tilt threshold' }) as HTMLInputElement;
    expect(input.readOnly).toBe(true);
    fireEvent.change(input, { target: { value: '9' } });
    expect(onChange).not.toHaveBeenCalled();
    fireEvent.click(screen.getByRole('button', { name: 'Unlock tilt threshold' }));
    expect(input.readOnly).toBe(false);
    fireEvent.change(input, { target: { value: '9' } });
    expect(onChange).toHaveBeenCalledTimes(1);
  });
});
