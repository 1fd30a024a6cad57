// @vitest-environment happy-dom
import { act, cleanup, fireEvent, render, screen } from '@testing-library/react';
import { afterEach, describe, expect, it, vi } from 'vitest';
import { DEADLINE_GRACE_MS, type CommandDecl } from './commands';
import { LinkError } from './errors';
import { createContext } from './fleet';
import { alwaysVisible } from './link';
import { createStore } from 'zustand/vanilla';
import { CommandButton, derivedStore, useNow } from './react';

afterEach(cleanup);

function setup() {
  const ctx = createContext(
    { id: 'm1', name: 'M1', kind: 'duet', simulated: true },
    { visibility: alwaysVisible, principal: () => ({ name: 'op', role: 'operator' }) },
  );
  const sent: string[] = [];
  const start: CommandDecl = {
    id: 'test.start',
    label: 'Start job',
    hazard: 'job',
    role: 'operator',
    available: (s) => (s.activity === 'idle' ? true : 'A job is already running'),
    perform: async () => {
      sent.push('start');
      return 'started';
    },
  };
  return { ctx, start, sent };
}

describe('CommandButton', () => {
  it('says on screen why a command is unavailable when tapped, and sends nothing', () => {
    const t = setup();
    t.ctx.snapshot.setState({ link: 'online', activity: 'running' });
    render(
      <CommandButton runner={t.ctx.commands} snapshot={t.ctx.snapshot} command={t.start} args={undefined} />,
    );
    const button = screen.getByTestId('cmd-test.start');
    expect(button.getAttribute('aria-disabled')).toBe('true');
    fireEvent.click(button);
    expect(screen.getByTestId('cmd-error-test.start').textContent).toBe(
      'Not available: A job is already running',
    );
    expect(screen.queryByTestId('confirm-dialog')).toBeNull();
    expect(t.sent).toEqual([]);
  });

  it('asks before a job command and sends it exactly once on confirmation', async () => {
    const t = setup();
    t.ctx.snapshot.setState({ link: 'online', activity: 'idle' });
    render(
      <CommandButton runner={t.ctx.commands} snapshot={t.ctx.snapshot} command={t.start} args={undefined} />,
    );
    fireEvent.click(screen.getByTestId('cmd-test.start'));
    expect(screen.getByTestId('confirm-dialog').textContent).toContain('Start job?');
    expect(t.sent).toEqual([]);
    await act(async () => {
      fireEvent.click(screen.getByTestId('confirm-yes'));
    });
    expect(t.sent).toEqual(['start']);
    expect(screen.queryByTestId('confirm-dialog')).toBeNull();
  });

  it('tells "not confirmed" apart from a failure: a silent controller past the deadline, then a refusal', async () => {
    vi.useFakeTimers();
    try {
      const t = setup();
      let answer: 'silent' | 'refuse' = 'silent';
      const pause: CommandDecl = {
        id: 'test.pause',
        label: 'Pause',
        hazard: 'motion',
        role: 'operator',
        deadlineMs: 2000,
        perform: () =>
          answer === 'silent'
            ? new Promise<string>(() => undefined)
            : Promise.reject(new LinkError('vendor', 'Busy: cannot pause now', { status: 409 })),
      };
      t.ctx.snapshot.setState({ link: 'online', activity: 'running', updatedAt: Date.now() });
      render(
        <CommandButton runner={t.ctx.commands} snapshot={t.ctx.snapshot} command={pause} args={undefined} />,
      );
      await act(async () => {
        fireEvent.click(screen.getByTestId('cmd-test.pause'));
        await vi.advanceTimersByTimeAsync(2000 + DEADLINE_GRACE_MS);
      });
      const unsure = screen.getByTestId('cmd-error-test.pause');
      expect(unsure.textContent).toMatch(/not confirmed: it may or may not have reached the machine/);
      expect(unsure.getAttribute('data-not-confirmed')).toBe('true');
      expect(screen.getByTestId('cmd-test.pause').getAttribute('title')).toMatch(
        /^Last attempt not confirmed/,
      );

      answer = 'refuse';
      t.ctx.snapshot.setState({ updatedAt: Date.now() });
      await act(async () => {
        fireEvent.click(screen.getByTestId('cmd-test.pause'));
        await vi.advanceTimersByTimeAsync(0);
      });
      const failed = screen.getByTestId('cmd-error-test.pause');
      expect(failed.textContent).toBe('Busy: cannot pause now');
      expect(failed.getAttribute('data-not-confirmed')).toBeNull();
      expect(screen.getByTestId('cmd-test.pause').getAttribute('title')).toMatch(/^Last attempt failed/);
    } finally {
      vi.useRealTimers();
    }
  });
});

describe('useNow', () => {
  it('twenty readers share one timer of their period, which stops with the last reader', () => {
    vi.useFakeTimers();
    try {
      const renders: number[] = [];
      function Clock({ i }: { i: number }) {
        const now = useNow(1000);
        renders[i] = (renders[i] ?? 0) + 1;
        return <span data-testid={`clock-${i}`}>{now}</span>;
      }
      const view = render(
        <>
          {Array.from({ length: 20 }, (_, i) => (
            <Clock key={i} i={i} />
          ))}
        </>,
      );
      expect(vi.getTimerCount()).toBe(1);
      const before = Number(screen.getByTestId('clock-7').textContent);
      act(() => {
        vi.advanceTimersByTime(3000);
      });
      expect(Number(screen.getByTestId('clock-7').textContent)).toBe(before + 3000);
      // Each reader rendered once per tick (plus its first render), not more.
      expect(renders.every((n) => n <= 4)).toBe(true);
      view.unmount();
      expect(vi.getTimerCount()).toBe(0);
    } finally {
      vi.useRealTimers();
    }
  });

  it('does not re-render a hidden page for the clock, and reads the time at once when shown', () => {
    vi.useFakeTimers();
    const hidden = vi.spyOn(document, 'hidden', 'get');
    try {
      let renders = 0;
      function Clock() {
        const now = useNow(1000);
        renders++;
        return <span data-testid="clock">{now}</span>;
      }
      const view = render(<Clock />);
      const start = Number(screen.getByTestId('clock').textContent);
      hidden.mockReturnValue(true);
      const before = renders;
      act(() => {
        vi.advanceTimersByTime(5000);
      });
      expect(renders).toBe(before);
      hidden.mockReturnValue(false);
      act(() => {
        document.dispatchEvent(new Event('visibilitychange'));
      });
      expect(Number(screen.getByTestId('clock').textContent)).toBe(start + 5000);
      view.unmount();
    } finally {
      hidden.mockRestore();
      vi.useRealTimers();
    }
  });
});

describe('derivedStore', () => {
  it('tells React only when the derived value changes, however often its sources do', () => {
    const a = createStore(() => ({ activity: 'idle', n: 0 }));
    const b = createStore(() => ({ activity: 'idle', n: 0 }));
    const running = () => [a, b].filter((s) => s.getState().activity === 'running').length;
    const store = derivedStore([a, b], running, (x, y) => x === y);
    const notify = vi.fn();
    const stop = store.subscribe(notify);
    // 1000 answers that change numbers but not the count: React hears nothing.
    for (let i = 0; i < 1000; i++) a.setState({ n: i });
    expect(notify).not.toHaveBeenCalled();
    expect(store.getSnapshot()).toBe(0);
    b.setState({ activity: 'running' });
    expect(notify).toHaveBeenCalledTimes(1);
    expect(store.getSnapshot()).toBe(1);
    stop();
    a.setState({ activity: 'running' });
    expect(notify).toHaveBeenCalledTimes(1);
  });
});
