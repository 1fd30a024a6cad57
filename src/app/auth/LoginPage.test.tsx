// @vitest-environment happy-dom
import { act, cleanup, fireEvent, render, screen } from '@testing-library/react';
import { afterEach, beforeEach, describe, expect, it, vi } from 'vitest';
import { authStore } from '../../fleet/auth';
import { sessionExtra } from './api';
import { LoginPage, nextPath } from './LoginPage';

function json(body: unknown, status = 200): Response {
  return new Response(JSON.stringify(body), { status, headers: { 'Content-Type': 'application/json' } });
}

describe('LoginPage', () => {
  let assign: ReturnType<typeof vi.fn>;
  beforeEach(() => {
    assign = vi.fn();
    vi.stubGlobal('location', { ...window.location, search: '?next=/m/laser-1', assign });
    authStore.setState({ mode: 'secured', user: null });
    sessionExtra.setState({ idleTimeoutS: null, elevation: null, expired: false, loaded: true });
  });
  afterEach(() => {
    cleanup();
    vi.unstubAllGlobals();
    vi.restoreAllMocks();
  });

  it('signs in through the gateway and goes where the user was headed', async () => {
    const fetchMock = vi.fn<typeof fetch>(() =>
      Promise.resolve(
        json({
          mode: 'secured',
          user: { name: 'otto', role: 'operator', machines: null },
          idleTimeoutS: 43200,
        }),
      ),
    );
    vi.stubGlobal('fetch', fetchMock);
    render(<LoginPage />);
    fireEvent.change(screen.getByLabelText('Name'), { target: { value: ' otto ' } });
    fireEvent.change(screen.getByLabelText('Password'), { target: { value: 'pw-123456' } });
    await act(async () => {
      fireEvent.click(screen.getByRole('button', { name: 'Sign in' }));
    });
    expect(fetchMock).toHaveBeenCalledTimes(1);
    const [url, init] = fetchMock.mock.calls[0]!;
    expect(url).toBe('/api/login');
    expect(JSON.parse(String(init?.body))).toEqual({ name: 'otto', password: 'pw-123456' });
    expect(authStore.getState().user).toEqual({ name: 'otto', role: 'operator', machines: null });
    expect(assign).toHaveBeenCalledWith('/m/laser-1');
  });

  it('shows the gateway’s reason when the login is refused, and clears the password', async () => {
    vi.stubGlobal(
      'fetch',
      vi.fn(() =>
        Promise.resolve(json({ error: 'too many failed logins: try again in 60 s', retryAfterS: 60 }, 429)),
      ),
    );
    render(<LoginPage />);
    fireEvent.change(screen.getByLabelText('Name'), { target: { value: 'otto' } });
    fireEvent.change(screen.getByLabelText('Password'), { target: { value: 'nope' } });
    await act(async () => {
      fireEvent.click(screen.getByRole('button', { name: 'Sign in' }));
    });
    expect(screen.getByTestId('login-error').textContent).toContain('too many failed logins');
    expect((screen.getByLabelText('Password') as HTMLInputElement).value).toBe('');
    expect(authStore.getState().user).toBeNull();
    expect(assign).not.toHaveBeenCalled();
  });

  it('says that no login is needed in open mode', () => {
    authStore.setState({ mode: 'open', user: null });
    render(<LoginPage />);
    expect(screen.getByTestId('login-open').textContent).toMatch(
      /anyone on this network can control these machines/,
    );
    expect(screen.queryByTestId('login-form')).toBeNull();
  });

  it('offers the supervisor PIN unlock to a signed-in operator', () => {
    authStore.setState({ mode: 'secured', user: { name: 'otto', role: 'operator', machines: null } });
    render(<LoginPage />);
    expect(screen.getByTestId('login-user').textContent).toBe('otto');
    fireEvent.click(screen.getByRole('button', { name: 'Supervisor unlock' }));
    expect(screen.getByTestId('pin-dialog')).toBeTruthy();
  });
});

describe('nextPath', () => {
  it('only follows paths on this console', () => {
    expect(nextPath('?next=/audit')).toBe('/audit');
    expect(nextPath('?next=//evil.example/x')).toBe('/');
    expect(nextPath('?next=https://evil.example')).toBe('/');
    expect(nextPath('')).toBe('/');
  });
});

describe('PIN unlock state', () => {
  afterEach(() => {
    cleanup();
    vi.unstubAllGlobals();
  });

  it('asks the gateway for the elevation when nobody has, and shows who unlocked the tablet', async () => {
    authStore.setState({ mode: 'secured', user: { name: 'sam', role: 'supervisor', machines: null } });
    sessionExtra.setState({ idleTimeoutS: null, elevation: null, expired: false, loaded: false });
    const until = new Date(Date.now() + 4 * 60_000).toISOString();
    const fetchMock = vi.fn<typeof fetch>(() =>
      Promise.resolve(
        json({
          mode: 'secured',
          user: { name: 'sam', role: 'supervisor', machines: null },
          idleTimeoutS: 43200,
          elevation: {
            supervisor: 'sam',
            until,
            operator: { name: 'otto', role: 'operator', machines: null },
          },
        }),
      ),
    );
    vi.stubGlobal('fetch', fetchMock);
    render(<LoginPage />);
    await act(async () => {
      await Promise.resolve();
    });
    expect(fetchMock.mock.calls[0]?.[0]).toBe('/api/session');
    expect((await screen.findByTestId('elevation')).textContent).toMatch(/Unlocked by sam · [34]:\d\d left/);
    expect(screen.getByTestId('login-user').textContent).toBe('otto');
    expect(screen.getByRole('button', { name: 'Lock now' })).toBeTruthy();
  });
});
