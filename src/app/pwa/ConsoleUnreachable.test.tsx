// @vitest-environment happy-dom
import { act, cleanup, fireEvent, render, screen } from '@testing-library/react';
import { afterEach, beforeEach, describe, expect, it, vi } from 'vitest';
import { authStore } from '../../fleet/auth';
import { fleetStore } from '../../fleet/fleet';
import { ConsoleUnreachable } from './ConsoleUnreachable';
import { reachStore } from './reach';

const answer = (body: unknown): Response =>
  new Response(JSON.stringify(body), { status: 200, headers: { 'Content-Type': 'application/json' } });

/** The console's server, which can be down (fetch rejects, as the browser's does). */
function server() {
  const s = {
    down: true,
    calls: [] as string[],
    fetch: vi.fn((url: string) => {
      s.calls.push(url);
      if (s.down) return Promise.reject(new TypeError('Failed to fetch'));
      return Promise.resolve(
        url.startsWith('/api/machines')
          ? answer({ machines: [] })
          : answer({ mode: 'secured', user: { name: 'ann', role: 'operator', machines: null } }),
      );
    }),
  };
  return s;
}

describe('booting while the console is unreachable', () => {
  beforeEach(() => {
    vi.useFakeTimers();
    reachStore.setState({ unreachable: false, offline: false, nextTryAt: null });
    fleetStore.setState({ status: 'loading', error: null, machines: [] });
    authStore.setState({ mode: 'unknown', user: null });
  });
  afterEach(() => {
    cleanup();
    vi.unstubAllGlobals();
    vi.useRealTimers();
  });

  it('says "Console unreachable — retrying", keeps trying, and loads the fleet by itself once it answers', async () => {
    const s = server();
    vi.stubGlobal('fetch', s.fetch);
    render(<ConsoleUnreachable />);
    expect(screen.queryByTestId('console-unreachable')).toBeNull();
    const { boot } = await import('../boot');
    const booted = boot();
    await act(() => vi.advanceTimersByTimeAsync(0));
    expect(screen.getByRole('heading', { name: 'Console unreachable — retrying' })).toBeTruthy();
    expect(screen.getByRole('status').textContent).toMatch(
      /does not answer\. Nothing is sent to any machine/,
    );
    // Not taken for open mode, not a fleet error.
    expect(authStore.getState().mode).toBe('unknown');
    expect(fleetStore.getState().status).toBe('loading');
    expect(screen.getByText(/Next try in \d+ s/)).toBeTruthy();

    await act(() => vi.advanceTimersByTimeAsync(10_000));
    expect(s.calls.length).toBeGreaterThan(2);
    expect(screen.getByTestId('console-unreachable')).toBeTruthy();

    s.down = false;
    const before = s.calls.length;
    await act(async () => {
      fireEvent.click(screen.getByRole('button', { name: 'Try now' }));
      await vi.advanceTimersByTimeAsync(0);
    });
    await act(() => booted);
    // Each asked once, side by side (boot asks for both at once: their order is not fixed).
    expect(s.calls.slice(before).sort()).toEqual(['/api/machines', '/api/session']);
    expect(screen.queryByTestId('console-unreachable')).toBeNull();
    expect(authStore.getState()).toMatchObject({ mode: 'secured', user: { name: 'ann' } });
    expect(fleetStore.getState().status).toBe('ready');
  });
});
