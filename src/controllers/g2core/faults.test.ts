import { describe, expect, it, vi } from 'vitest';
import { advance, FaultGate, faultHarness, within, type Fault } from '../../fleet/faults.test-util';
import { createContext } from '../../fleet/fleet';
import { alwaysVisible } from '../../fleet/link';
import { simulatorHandlers } from '../../fleet/msw';
import { jsonResponse, type Simulator } from '../../fleet/sim';
import type { LinkState } from '../../fleet/types';
import { G2coreSession, LIVENESS_MS } from './session';
import { G2coreSimulator } from './sim/simulator';

/**
 * Issue 15 for g2core: a failed request (the console server's 502/504, no answer, a cut answer)
 * is a link problem, never a verdict ("no /version", "no axis modes", "cannot list operations");
 * verdicts are re-checked on every reconnect; silence is a fault; the machine is back within 5 s
 * of the fault ending, with the same session.
 */

const { server, cleanup } = faultHarness();
let seq = 0;

/** What a request-specific wrapper may answer instead of the simulator. */
type Override = (req: Request, path: string) => Response | null;

function setup(override?: Override) {
  const id = `fault-cnc-${++seq}`;
  const sim = new G2coreSimulator({ id, name: 'CNC' });
  const served: Simulator = override
    ? {
        kind: 'g2core',
        fetch: (req, path) => Promise.resolve(override(req, path) ?? sim.fetch(req, path)),
        dispose: () => sim.dispose(),
      }
    : sim;
  const gate = new FaultGate(served);
  server.use(...simulatorHandlers(id, gate));
  const ctx = createContext(
    { id, name: 'CNC', kind: 'g2core', simulated: true },
    { visibility: alwaysVisible, principal: () => ({ name: 'tester', role: 'supervisor' }) },
  );
  const session = new G2coreSession(ctx);
  const states = new Set<LinkState>();
  const problems: string[] = [];
  const unsub = ctx.snapshot.subscribe((s) => {
    states.add(s.link);
    if (s.problem) problems.push(s.problem.message);
  });
  cleanup.push(() => {
    unsub();
    session.stop();
    gate.dispose();
  });
  const link = () => ctx.snapshot.getState().link;
  const fresh = (since: number) => link() === 'online' && (ctx.snapshot.getState().updatedAt ?? 0) > since;
  const warnings = () =>
    ctx.log.store
      .getState()
      .entries.filter((e) => e.source === 'protocol')
      .map((e) => e.text);
  return { sim, gate, ctx, session, link, fresh, states, problems, warnings };
}

/** A long slow jog: every status report changes (answers longer than a cut leaves). */
async function moving(s: G2coreSession): Promise<void> {
  await s.ctx.commands.run(s.jog, { axis: 'x', distance: 200, feed: 300 });
  await advance(500);
  expect(s.ctx.snapshot.getState().activity).toBe('running');
}

const VERDICTS: LinkState[] = ['protocol-error', 'needs-login'];
const VERDICT_WORDS = /GET \/version failed|Could not read axis modes|not supported/;
const FAILED_REQUESTS: Fault[] = ['gateway', 'gateway-body', 'network', 'cut'];

describe('g2core: a failed request is a link problem, never a verdict', () => {
  it.each(FAILED_REQUESTS)(
    'online, then every request fails (%s) for 20 s: reconnecting, no verdict, back within 5 s',
    async (fault) => {
      // The longest delays the backoff's jitter allows: a retry cannot land right after the fault by luck.
      vi.spyOn(Math, 'random').mockReturnValue(0.999);
      const t = setup();
      t.session.start();
      await within(() => t.link() === 'online', 2000);
      await moving(t.session);
      t.gate.fault = fault;
      await within(() => t.link() !== 'online', 2000);
      expect(t.link()).toBe('reconnecting');
      if (fault === 'cut') expect(t.ctx.snapshot.getState().problem?.message).toMatch(/cut/);
      await advance(20_000);
      expect(['reconnecting', 'offline']).toContain(t.link());
      expect(t.ctx.snapshot.getState().problem?.kind).not.toBe('protocol');
      // It keeps trying on its own, no more than 4 s apart.
      const tries = t.gate.seen.length;
      await advance(4500);
      expect(t.gate.seen.length).toBeGreaterThan(tries);

      t.gate.fault = 'none';
      const healed = Date.now();
      await within(() => t.fresh(healed), 5000);
      expect([...t.states].filter((s) => VERDICTS.includes(s))).toEqual([]);
      expect(t.warnings().filter((w) => VERDICT_WORDS.test(w))).toEqual([]);
      expect(t.session.detail.getState().version).not.toBeNull();
    },
  );

  it.each(FAILED_REQUESTS)(
    'failing from the start (%s): never "no /version" or "no axis modes"; version and axes read once back',
    async (fault) => {
      vi.spyOn(Math, 'random').mockReturnValue(0.999);
      const t = setup();
      t.gate.fault = fault;
      t.session.start();
      await advance(12_000);
      expect(['reconnecting', 'offline']).toContain(t.link());
      expect(t.warnings().filter((w) => VERDICT_WORDS.test(w))).toEqual([]);
      expect(t.session.detail.getState().version).toBeNull();

      t.gate.fault = 'none';
      const healed = Date.now();
      await within(() => t.fresh(healed), 5000);
      expect(t.session.detail.getState().version).not.toBeNull();
      expect(t.session.detail.getState().overrides.mfoe).not.toBeNull();
      expect([...t.states].filter((s) => VERDICTS.includes(s))).toEqual([]);
      expect(t.warnings().filter((w) => VERDICT_WORDS.test(w))).toEqual([]);
    },
  );

  it('answers cut after 20 bytes are failed requests: several in a row are a link problem, not "Online (stale)"', async () => {
    const t = setup();
    t.session.start();
    await within(() => t.link() === 'online', 2000);
    await moving(t.session);
    t.gate.fault = 'cut';
    const ms = await within(() => t.link() !== 'online', 5000);
    expect(ms).toBeLessThan(1000);
    expect(t.ctx.snapshot.getState().problem).toMatchObject({ kind: 'network' });
    await advance(10_000);
    expect(['reconnecting', 'offline']).toContain(t.link());
    expect(t.states.has('protocol-error')).toBe(false);
    t.gate.fault = 'none';
    const healed = Date.now();
    await within(() => t.fresh(healed), 5000);
  });

  it.each([
    { status: 404, header: true },
    { status: 405, header: false },
    { status: 502, header: true },
  ])(
    'GET /operation answered by the console server itself ($status) is not "cannot list operations"',
    async ({ status, header }) => {
      let failing = true;
      const t = setup((req, path) =>
        failing && path === '/operation' && req.method === 'GET'
          ? new Response(JSON.stringify({ error: 'the controller is not reachable', gateway: true }), {
              status,
              headers: {
                'Content-Type': 'application/json',
                ...(header ? { 'X-Shopdeck-Gateway': 'error' } : {}),
              },
            })
          : null,
      );
      t.session.start();
      await within(() => t.link() === 'online', 2000);
      let listed = 0;
      const inner = t.sim.fetch.bind(t.sim);
      t.sim.fetch = (req, path) => {
        if (path === '/operation' && req.method === 'GET') listed++;
        return inner(req, path);
      };
      // Motion another console started: the console asks for the list of operations.
      await inner(
        new Request('http://sim/operation', {
          method: 'POST',
          body: JSON.stringify({ optype: 'run', value: 'G1 X300 F300' }),
        }),
        '/operation',
      );
      await advance(3000);
      expect(t.gate.seen.filter((p) => p === '/operation').length).toBeGreaterThan(0);
      expect(t.session.opsListSupported).toBe(true);
      expect(t.warnings().filter((w) => VERDICT_WORDS.test(w))).toEqual([]);
      failing = false;
      await within(() => listed > 0, 3000);
      await advance(500);
      expect(Object.values(t.session.detail.getState().ops).some((o) => o.purpose === 'other')).toBe(true);
    },
  );
});

describe('g2core: verdicts are re-checked on every reconnect', () => {
  it('"no /version" from the server itself is a warning, and asked again after an outage', async () => {
    let hasVersion = false;
    const t = setup((_req, path) =>
      !hasVersion && path === '/version'
        ? jsonResponse({ status: { code: 100, description: 'Unrecognized command or config name' } }, 404)
        : null,
    );
    t.session.start();
    await within(() => t.link() === 'online', 2000);
    expect(t.warnings().filter((w) => /GET \/version failed/.test(w))).toHaveLength(1);
    expect(t.session.detail.getState().version).toBeNull();
    await advance(3000);
    // Once per (re)connect, not every poll.
    expect(t.gate.seen.filter((p) => p === '/version')).toHaveLength(1);

    hasVersion = true;
    t.gate.fault = 'network';
    await within(() => t.link() !== 'online', 2000);
    await advance(3000);
    t.gate.fault = 'none';
    const healed = Date.now();
    await within(() => t.fresh(healed), 5000);
    expect(t.session.detail.getState().version).not.toBeNull();
    expect(t.ctx.snapshot.getState().identity).toMatch(/g2core/);
  });

  it('"cannot list operations" from the server itself is asked again after a reconnect', async () => {
    const t = setup((req, path) =>
      path === '/operation' && req.method === 'GET'
        ? jsonResponse({ status: { code: 100, description: 'Unrecognized command or config name' } }, 404)
        : null,
    );
    t.session.start();
    await within(() => t.link() === 'online', 2000);
    await t.sim.fetch(
      new Request('http://sim/operation', {
        method: 'POST',
        body: JSON.stringify({ optype: 'run', value: 'G1 X300 F300' }),
      }),
      '/operation',
    );
    await within(() => !t.session.opsListSupported, 3000);
    const lists = () => t.gate.seen.filter((p) => p === '/operation').length;
    await advance(3000);
    // Settled: not asked again while the link holds.
    const asked = lists();
    await advance(3000);
    expect(lists()).toBe(asked);
    t.gate.fault = 'network';
    await within(() => t.link() !== 'online', 2000);
    t.gate.fault = 'none';
    const healed = Date.now();
    await within(() => t.fresh(healed), 5000);
    // Asked again after the reconnect (and the server still says no).
    await within(() => lists() > asked, 3000);
    await within(() => !t.session.opsListSupported, 3000);
  });
});

describe('g2core: silence is a fault', () => {
  it(`a silent link (requests accepted, nothing answered) is down within ${LIVENESS_MS + 500} ms, back within 5 s`, async () => {
    const t = setup();
    t.session.start();
    await within(() => t.link() === 'online', 2000);
    await moving(t.session);
    t.gate.fault = 'silent';
    const ms = await within(() => t.link() !== 'online', 5000);
    expect(ms).toBeLessThanOrEqual(LIVENESS_MS + 500);
    expect(t.ctx.snapshot.getState().problem?.kind).toBe('timeout');
    await advance(10_000);
    expect(t.link()).not.toBe('online');
    t.gate.fault = 'none';
    const healed = Date.now();
    await within(() => t.fresh(healed), 5000);
    expect([...t.states].filter((s) => VERDICTS.includes(s))).toEqual([]);
  });

  it('a slow link (answers after 2 s) is not silence', async () => {
    let slowMs = 0;
    const t = setup();
    const inner = t.sim.fetch.bind(t.sim);
    t.sim.fetch = async (req, path) => {
      if (slowMs > 0) await new Promise((r) => setTimeout(r, slowMs));
      return inner(req, path);
    };
    t.session.start();
    await within(() => t.link() === 'online', 2000);
    slowMs = 2000;
    const offline: LinkState[] = [];
    const unsub = t.ctx.snapshot.subscribe((s) => {
      if (s.link !== 'online') offline.push(s.link);
    });
    await advance(10_000);
    unsub();
    expect(offline).toEqual([]);
    expect(t.fresh(Date.now() - 3000)).toBe(true);
  });

  it('another g2core keeps updating while one is silent', async () => {
    const a = setup();
    const b = setup();
    a.session.start();
    b.session.start();
    await within(() => a.link() === 'online' && b.link() === 'online', 2000);
    a.gate.fault = 'silent';
    const before = b.ctx.snapshot.getState().updatedAt ?? 0;
    await advance(8000);
    expect(a.link()).not.toBe('online');
    expect(b.link()).toBe('online');
    expect(b.ctx.snapshot.getState().updatedAt ?? 0).toBeGreaterThan(before + 7000);
  });
});
