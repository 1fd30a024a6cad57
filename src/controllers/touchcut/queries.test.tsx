// @vitest-environment happy-dom
import { act, cleanup, renderHook } from '@testing-library/react';
import { setupServer } from 'msw/node';
import { afterAll, afterEach, beforeAll, beforeEach, describe, expect, it, vi } from 'vitest';
import { createContext } from '../../fleet/fleet';
import { alwaysVisible } from '../../fleet/link';
import { simulatorHandlers } from '../../fleet/msw';
import { setApiOrigin } from '../../fleet/origin';
import { useOpenData, useStats } from './queries';
import { TouchcutSession } from './session';
import { SIM_MONITOR_API_KEY, TouchcutSimulator } from './sim/simulator';
import { setTouchcutUnits } from './state';
import { localDate, presetRange } from './stats';
import { viaGateway, type GatewayStandIn } from './testkit';

/** On-demand reads through the query layer, against the simulator behind the gateway stand-in. */

let sim: TouchcutSimulator;
let gw: GatewayStandIn;
let session: TouchcutSession;
const server = setupServer();

beforeAll(() => {
  setApiOrigin('http://shopdeck.test');
  server.listen({ onUnhandledRequest: 'error' });
});
afterAll(() => server.close());

beforeEach(async () => {
  vi.useFakeTimers({ toFake: ['setTimeout', 'clearTimeout', 'setInterval', 'clearInterval', 'Date'] });
  setTouchcutUnits('default');
  sim = new TouchcutSimulator({ id: 'tcq', name: 'Plasma', tickMs: 100 });
  sim.autoOperator = false;
  gw = viaGateway(sim, SIM_MONITOR_API_KEY);
  server.resetHandlers(...simulatorHandlers('tcq', gw));
  session = new TouchcutSession(
    createContext(
      { id: 'tcq', name: 'Plasma', kind: 'touchcut', simulated: true },
      { visibility: alwaysVisible, principal: () => ({ name: 'sam', role: 'viewer' }) },
    ),
  );
  session.start();
  await vi.advanceTimersByTimeAsync(1500);
  expect(session.ctx.snapshot.getState().link).toBe('online');
});
afterEach(() => {
  cleanup();
  session.stop();
  sim.dispose();
  vi.useRealTimers();
});

const asked = (what: string) =>
  gw.fromBrowser.filter((r) => r.path.includes(`/rest/v1/${what}`)).map((r) => decodeURIComponent(r.path));
const settle = (ms: number) => act(() => vi.advanceTimersByTimeAsync(ms));

describe('touchcut programs through the query layer', () => {
  it('reads the page in full, refreshes it with changed data only (merged), a new page and Reload in full', async () => {
    const { result } = renderHook(() => useOpenData(session.programs));
    await settle(100);
    expect(asked('programs')).toHaveLength(1);
    expect(asked('programs')[0]).not.toContain('onlyChangedData');
    const total =
      result.current.data && !Array.isArray(result.current.data) ? result.current.data.total : null;
    expect(total).toBeGreaterThan(0);

    await settle(5000);
    expect(asked('programs')).toHaveLength(2);
    expect(asked('programs')[1]).toContain('onlyChangedData=true');
    // The refresh sent only the active program: the list stays, merged.
    const merged = result.current.data as Record<string, unknown>;
    expect(merged.total).toBe(total);
    expect(Array.isArray(merged.programs)).toBe(true);
    expect(merged.activeProgram).toBeTruthy();

    act(() => session.programs.page(25, 25));
    await settle(100);
    expect(asked('programs')).toHaveLength(3);
    expect(asked('programs')[2]).toMatch(/offset=25&limit=25$/);
    expect(result.current.offset).toBe(25);

    act(() => session.programs.reload());
    await settle(100);
    expect(asked('programs')).toHaveLength(4);
    expect(asked('programs')[3]).not.toContain('onlyChangedData');
  });

  it('asks nothing while the machine needs a login', async () => {
    session.ctx.snapshot.setState({ link: 'needs-login' });
    const { result } = renderHook(() => useOpenData(session.unloader));
    await settle(20_000);
    expect(asked('unloader')).toHaveLength(0);
    expect(result.current.data).toBeNull();
  });
});

describe('touchcut statistics through the query layer', () => {
  const today = localDate(new Date());
  const A = { ...presetRange('lastWeek', today), condensed: false };
  const B = { ...presetRange('yesterday', today), condensed: true };

  it('keys each read by range and units: a range shown again comes from the cache, Show on it reads again', async () => {
    const { result } = renderHook(() => useStats(session.stats));
    expect(result.current.request).toBeNull();
    await settle(100);
    expect(asked('stats')).toHaveLength(0); // no range, no read

    await act(() => session.stats.load(A));
    await settle(100);
    expect(asked('stats')).toHaveLength(1);
    expect(result.current.data?.periods).toHaveLength(7);

    await act(() => session.stats.load(B));
    await settle(100);
    expect(asked('stats')).toHaveLength(2);
    expect(asked('stats')[1]).toContain('condensed=true');

    await act(() => session.stats.load(A)); // back to A: shown at once from the cache
    expect(result.current.data?.periods).toHaveLength(7);
    await settle(100);
    expect(asked('stats')).toHaveLength(2);

    await act(() => session.stats.load(A)); // "Show" on the range shown: read again
    await settle(100);
    expect(asked('stats')).toHaveLength(3);

    act(() => setTouchcutUnits('imperial')); // the units are part of the key
    await settle(100);
    expect(asked('stats')).toHaveLength(4);
    expect(asked('stats')[3]).toContain('units=imperial');
    expect(result.current.data?.units).toBe('imperial');
  });
});
