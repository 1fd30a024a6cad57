import { describe, expect, it, vi } from 'vitest';
import { createContext } from '../../fleet/fleet';
import { alwaysVisible } from '../../fleet/link';
import { simulatorHandlers } from '../../fleet/msw';
import { KEY_REFUSED } from './auth';
import { AUTH_RETRY_BASE_MS, AUTH_RETRY_MAX_MS } from '../../fleet/faults';
import { advance, FaultGate, faultHarness, within, type Fault } from '../../fleet/faults.test-util';
import { TouchcutSession } from './session';
import { SIM_MONITOR_API_KEY, TouchcutSimulator } from './sim/simulator';
import { viaGateway } from './testkit';
import type { Simulator } from '../../fleet/sim';

/**
 * Issue 15 for TouchCut: failed requests are link problems (never "needs login"), a refused API
 * key (the gateway's credentials) is tried again on its own, slowly, a typed login never is,
 * silence is down within 5 s, and the machine is back within 5 s of the fault ending.
 */

const { server, cleanup } = faultHarness();
let seq = 0;

/** `apiKey` null: the machines file has none. */
function setup(apiKey: string | null = SIM_MONITOR_API_KEY, latency: { each: number } = { each: 0 }) {
  const id = `fault-tc-${++seq}`;
  const sim = new TouchcutSimulator({ id, name: 'Plasma', tickMs: 100 });
  sim.autoOperator = false;
  const gw = viaGateway(sim, apiKey ?? undefined);
  const gate = new FaultGate(slowLink(gw, latency));
  server.use(...simulatorHandlers(id, gate));
  const ctx = createContext(
    { id, name: 'Plasma', kind: 'touchcut', simulated: true },
    {
      visibility: alwaysVisible,
      now: () => Date.now(),
      principal: () => ({ name: 'sam', role: 'operator' }),
    },
  );
  const session = new TouchcutSession(ctx);
  cleanup.push(() => {
    session.stop();
    gate.dispose();
  });
  const statusReads = () => sim.requests.filter((r) => r.path.startsWith('/rest/v1/status')).length;
  return { sim, gw, gate, ctx, session, statusReads, link: () => ctx.snapshot.getState().link };
}

/** A link on which every request waits `each` ms on its way there and back. */
function slowLink(inner: Simulator, latency: { each: number }): Simulator {
  const wait = (ms: number) => new Promise((r) => setTimeout(r, ms));
  return {
    kind: inner.kind,
    fetch: async (req, path) => {
      const ms = latency.each;
      if (ms > 0) await wait(ms);
      const res = await inner.fetch(req, path);
      if (ms > 0) await wait(ms);
      return res;
    },
    controls: () => inner.controls?.() ?? [],
    dispose: () => inner.dispose(),
  };
}

describe('TouchCut: the gateway API key refused', () => {
  it('refused (401) for 5 s, then accepted again: back online by itself within 5 s', async () => {
    const { gw, ctx, session, link } = setup();
    session.start();
    await within(() => link() === 'online', 3000);
    gw.apiKey = 'a-key-that-was-revoked';
    await within(() => link() === 'needs-login', 3000);
    const snap = ctx.snapshot.getState();
    expect(snap.problem?.message).toBe(KEY_REFUSED);
    expect(snap.problem?.message).toMatch(/machines file/);
    expect(snap.retryAt).not.toBeNull();
    await advance(5000);
    gw.apiKey = SIM_MONITOR_API_KEY;
    await within(() => link() === 'online', 5000);
    expect(session.store.getState().auth).toMatchObject({ mode: 'key', reason: null });
  });

  it('a key that stays wrong is tried a few times quickly, then at most once a minute', async () => {
    vi.spyOn(Math, 'random').mockReturnValue(0);
    const { sim, gw, session, statusReads, link } = setup();
    session.start();
    await within(() => link() === 'online', 3000);
    gw.apiKey = 'wrong';
    await within(() => link() === 'needs-login', 3000);
    const times: number[] = [];
    let last = statusReads();
    for (let t = 0; t < 15 * 60_000; t += 250) {
      await vi.advanceTimersByTimeAsync(250);
      const n = statusReads();
      if (n !== last) times.push(Date.now());
      last = n;
    }
    const gaps = times.slice(1).map((t, i) => t - (times[i] ?? 0));
    // A few quick tries, then a minute apart (the lowest jitter: 48 s), never more than a minute.
    expect(times.length).toBeGreaterThan(10);
    expect(times.length).toBeLessThan(30);
    // The first tries 2.5 s apart: credentials right again after a few seconds are back within 5 s.
    expect(gaps.slice(0, 3).every((g) => g <= AUTH_RETRY_BASE_MS + 500)).toBe(true);
    expect(gaps.slice(-8).every((g) => g >= AUTH_RETRY_MAX_MS * 0.8 - 1000)).toBe(true);
    expect(gaps.every((g) => g <= AUTH_RETRY_MAX_MS + 1000)).toBe(true);
    expect(link()).toBe('needs-login');
    // Accepted again: back at the next try, within a minute.
    gw.apiKey = SIM_MONITOR_API_KEY;
    await within(() => link() === 'online', AUTH_RETRY_MAX_MS + 1500);
    expect(sim.requests.length).toBeGreaterThan(0);
  });

  it('a typed user login that expired waits for a login: nothing is retried on the user’s behalf', async () => {
    const { sim, session, statusReads, link } = setup(null);
    session.start();
    await within(() => link() === 'needs-login', 3000);
    sim.jwtTtlMs = 10_000;
    await session.login({ username: 'operator', password: 'operator' });
    await within(() => link() === 'online', 3000);
    await within(() => link() === 'needs-login', 15_000);
    expect(session.store.getState().auth.reason).toMatch(/login of operator expired/);
    const reads = statusReads();
    const logins = sim.requests.filter((r) => r.path.startsWith('/rest/v1/auth')).length;
    await advance(5 * 60_000);
    expect(statusReads()).toBe(reads);
    expect(sim.requests.filter((r) => r.path.startsWith('/rest/v1/auth')).length).toBe(logins);
    expect(link()).toBe('needs-login');
  });

  it("the console server's own 401 (no console login) is not TouchCut refusing the key", async () => {
    const { gate, ctx, session, link } = setup();
    session.start();
    await within(() => link() === 'online', 3000);
    gate.body401 = {
      status: 401,
      body: JSON.stringify({ error: 'sign in to the console first', gateway: true }),
    };
    gate.fault = 'unauthorized';
    await within(() => link() !== 'online', 5000);
    expect(link()).not.toBe('needs-login');
    expect(ctx.snapshot.getState().problem?.message).toMatch(/sign in to the console/);
    gate.fault = 'none';
    await within(() => link() === 'online', 5000);
  });
});

describe('TouchCut: failed requests and silence', () => {
  it.each<Fault>(['gateway', 'gateway-body', 'network', 'cut'])(
    'status fails (%s): reconnecting, never needs-login or a protocol error; back within 5 s',
    async (fault) => {
      vi.spyOn(Math, 'random').mockReturnValue(0.999);
      const { gate, ctx, session, link } = setup();
      session.start();
      await within(() => link() === 'online', 3000);
      gate.fault = fault;
      await within(() => link() !== 'online', 5000);
      await advance(20_000);
      expect(['reconnecting', 'offline']).toContain(link());
      expect(ctx.snapshot.getState().problem?.kind).not.toBe('protocol');
      gate.fault = 'none';
      await within(() => link() === 'online', 5000);
    },
  );

  it('a silent link is down within 5 s and back within 5 s; the request still waits its timeout', async () => {
    const { gate, ctx, session, link } = setup();
    session.start();
    await within(() => link() === 'online', 3000);
    gate.fault = 'silent';
    await within(() => link() !== 'online', 5000);
    expect(ctx.snapshot.getState().problem?.message).toMatch(/has not answered/);
    await advance(12_000);
    expect(link()).not.toBe('online');
    gate.fault = 'none';
    await within(() => link() === 'online', 5000);
  });

  it('another machine keeps updating meanwhile', async () => {
    const a = setup();
    const b = setup();
    a.session.start();
    b.session.start();
    await within(() => a.link() === 'online' && b.link() === 'online', 3000);
    a.gate.fault = 'silent';
    const before = b.ctx.snapshot.getState().updatedAt ?? 0;
    await advance(8000);
    expect(a.link()).not.toBe('online');
    expect(b.link()).toBe('online');
    expect(b.ctx.snapshot.getState().updatedAt ?? 0).toBeGreaterThan(before + 6000);
  });
});

describe('TouchCut: a slow link that still delivers is ridden through', () => {
  it.each([
    // The fault matrix (plain HTTP): 2 s each way, a request takes 4 s.
    { each: 2000, firstDataMs: 6000 },
    // 2 s each way over TLS: TCP and TLS handshakes, then the request: 12 to 16 s.
    { each: 8000, firstDataMs: 18_000 },
  ])(
    '$each ms each way: data within $firstDataMs ms, then never down while answers arrive',
    async ({ each, firstDataMs }) => {
      const latency = { each: 0 };
      const { ctx, session, link } = setup(SIM_MONITOR_API_KEY, latency);
      session.start();
      await within(() => link() === 'online', 3000);
      latency.each = each;
      const t0 = Date.now();
      await within(
        () => link() === 'online' && (ctx.snapshot.getState().updatedAt ?? 0) > t0 + 2 * each,
        firstDataMs,
      );
      // The request's own timeout is longer than the slowest of these answers.
      const states = new Set<string>();
      const unsub = ctx.snapshot.subscribe((s) => states.add(s.link));
      const before = ctx.snapshot.getState().updatedAt ?? 0;
      await advance(60_000);
      unsub();
      expect([...states]).toEqual(['online']);
      expect(ctx.snapshot.getState().updatedAt ?? 0).toBeGreaterThan(before + 30_000);
      latency.each = 0;
      await advance(10_000);
      expect(link()).toBe('online');
    },
  );

  it('a silence after a slow period is still detected, and back within 5 s', async () => {
    const latency = { each: 2000 };
    const { gate, session, link } = setup(SIM_MONITOR_API_KEY, latency);
    session.start();
    await within(() => link() === 'online', 10_000);
    await advance(12_000);
    expect(link()).toBe('online');
    gate.fault = 'silent';
    // The window on this link: a poll period and 1.5 × 4 s (7 s), from the last answer, which
    // may be one already on its way back when the silence began (up to 4 s later).
    const t = await within(() => link() !== 'online', 12_000);
    expect(t).toBeGreaterThan(4000);
    gate.fault = 'none';
    await within(() => link() === 'online', 5000);
  });
});
