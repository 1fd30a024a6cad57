import { afterEach, beforeEach, describe, expect, it, vi } from 'vitest';
import { authStore } from '../../fleet/auth';
import { auditQuery, elevate, fetchSession, logout, sessionExtra, trackActivity } from './api';

function json(body: unknown, status = 200): Response {
  return new Response(JSON.stringify(body), { status, headers: { 'Content-Type': 'application/json' } });
}

describe('auth api', () => {
  beforeEach(() => {
    vi.useFakeTimers();
    vi.setSystemTime(new Date('2026-01-05T10:00:00Z'));
  });
  afterEach(() => {
    vi.useRealTimers();
    vi.unstubAllGlobals();
  });

  it('a PIN unlock makes the supervisor the user until it runs out, then follows the gateway back', async () => {
    authStore.setState({ mode: 'secured', user: { name: 'otto', role: 'operator', machines: null } });
    const elevated = {
      mode: 'secured',
      user: { name: 'sam', role: 'supervisor', machines: null },
      idleTimeoutS: 43200,
      elevation: {
        supervisor: 'sam',
        until: '2026-01-05T10:05:00.000Z',
        operator: { name: 'otto', role: 'operator', machines: null },
      },
    };
    const back = {
      mode: 'secured',
      user: { name: 'otto', role: 'operator', machines: null },
      idleTimeoutS: 43200,
      elevation: null,
    };
    const fetchMock = vi.fn<typeof fetch>((url) =>
      Promise.resolve(json(String(url) === '/api/elevate' ? elevated : back)),
    );
    vi.stubGlobal('fetch', fetchMock);
    await elevate('sam', '4711');
    expect(authStore.getState().user?.role).toBe('supervisor');
    expect(sessionExtra.getState().elevation).toEqual({
      supervisor: 'sam',
      operator: 'otto',
      until: Date.parse('2026-01-05T10:05:00Z'),
    });
    await vi.advanceTimersByTimeAsync(5 * 60_000 + 1000);
    expect(fetchMock.mock.calls.map((c) => String(c[0]))).toEqual(['/api/elevate', '/api/session']);
    expect(authStore.getState().user).toEqual({ name: 'otto', role: 'operator', machines: null });
    expect(sessionExtra.getState().elevation).toBeNull();
  });

  it('reports user activity at most once a minute, only when signed in', async () => {
    vi.stubGlobal(
      'fetch',
      vi.fn<typeof fetch>(() => Promise.resolve(json({ mode: 'secured', user: null }))),
    );
    await fetchSession();
    const target = new EventTarget();
    const stop = trackActivity(target as unknown as Window, 60_000);
    const fetchMock = vi.fn<typeof fetch>(() => Promise.resolve(json({})));
    vi.stubGlobal('fetch', fetchMock);
    target.dispatchEvent(new Event('pointerdown'));
    expect(fetchMock).not.toHaveBeenCalled();
    authStore.setState({ mode: 'secured', user: { name: 'otto', role: 'operator', machines: null } });
    target.dispatchEvent(new Event('pointerdown'));
    target.dispatchEvent(new Event('keydown'));
    expect(fetchMock).toHaveBeenCalledTimes(1);
    expect(fetchMock.mock.calls[0]![0]).toBe('/api/session/activity');
    vi.advanceTimersByTime(61_000);
    target.dispatchEvent(new Event('keydown'));
    expect(fetchMock).toHaveBeenCalledTimes(2);
    stop();
    vi.advanceTimersByTime(61_000);
    target.dispatchEvent(new Event('keydown'));
    expect(fetchMock).toHaveBeenCalledTimes(2);
  });

  it('signing out clears this browser’s storage (unsaved drafts of machine settings), even when the gateway is unreachable', async () => {
    const storage = (): Storage => {
      const m = new Map<string, string>();
      return {
        get length() {
          return m.size;
        },
        clear: () => m.clear(),
        getItem: (k: string) => m.get(k) ?? null,
        key: (i: number) => [...m.keys()][i] ?? null,
        removeItem: (k: string) => void m.delete(k),
        setItem: (k: string, v: string) => void m.set(k, v),
      };
    };
    for (const reachable of [true, false]) {
      const local = storage();
      const session = storage();
      local.setItem('shopdeck.form.plasma-1.settings', '{"thcVoltage":"130"}');
      session.setItem('anything', '1');
      vi.stubGlobal('localStorage', local);
      vi.stubGlobal('sessionStorage', session);
      const fetchMock = vi.fn<typeof fetch>(() =>
        reachable
          ? Promise.resolve(json({ mode: 'secured', user: null }))
          : Promise.reject(new TypeError('offline')),
      );
      vi.stubGlobal('fetch', fetchMock);
      authStore.setState({ mode: 'secured', user: { name: 'sue', role: 'supervisor', machines: null } });
      await logout();
      expect(fetchMock.mock.calls[0]?.[0]).toBe('/api/logout');
      expect(fetchMock.mock.calls[0]?.[1]?.method).toBe('POST');
      expect(local.length, `reachable: ${reachable}`).toBe(0);
      expect(session.length, `reachable: ${reachable}`).toBe(0);
      expect(authStore.getState().user).toBeNull();
      vi.unstubAllGlobals();
    }
  });

  it('builds audit queries with ISO times', () => {
    expect(
      auditQuery({ machine: ' laser-1 ', user: '', from: '2026-01-05T10:00:00Z' }, { offset: 50, limit: 50 }),
    ).toBe('?machine=laser-1&from=2026-01-05T10%3A00%3A00.000Z&offset=50&limit=50');
    expect(auditQuery({ to: 'not a date' })).toBe('');
  });
});

describe('a screen whose session is gone (issue 33)', () => {
  afterEach(() => {
    vi.unstubAllGlobals();
    sessionExtra.setState({ signedOut: false });
  });

  it('the console’s own 401 on a read makes the page ask who is signed in: gone → signed out, the sign-in shown', async () => {
    const { gatewayError } = await import('../../fleet/http');
    authStore.setState({ mode: 'secured', user: { name: 'vera', role: 'viewer', machines: null } });
    const fetchMock = vi.fn<typeof fetch>(() =>
      Promise.resolve(
        json({ mode: 'secured', user: null, idleTimeoutS: null, elevation: null, expired: false }),
      ),
    );
    vi.stubGlobal('fetch', fetchMock);
    gatewayError(new Response('{}', { status: 401, headers: { 'X-Shopdeck-Gateway': 'error' } }), {
      error: 'log in first',
    });
    // Nothing but the console's own 401 asks: the page's listener (api.ts) does.
    await vi.waitFor(() => expect(sessionExtra.getState().signedOut).toBe(true));
    expect(fetchMock.mock.calls.map((c) => String(c[0]))).toEqual(['/api/session']);
    expect(authStore.getState().user).toBeNull();
    expect(sessionExtra.getState().signedOut).toBe(true);
  });

  it('a controller’s own 401 (a TouchCut refusing its key) is that machine’s answer: the session is not asked about', async () => {
    const { gatewayError } = await import('../../fleet/http');
    authStore.setState({ mode: 'secured', user: { name: 'vera', role: 'viewer', machines: null } });
    const fetchMock = vi.fn<typeof fetch>(() => Promise.resolve(json({})));
    vi.stubGlobal('fetch', fetchMock);
    expect(gatewayError(new Response('{}', { status: 401 }), { error: 'invalid api key' })).toBeNull();
    await Promise.resolve();
    expect(fetchMock).not.toHaveBeenCalled();
    expect(authStore.getState().user?.name).toBe('vera');
    expect(sessionExtra.getState().signedOut).toBe(false);
  });
});
