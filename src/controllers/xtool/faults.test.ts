import { describe, expect, it, vi } from 'vitest';
import { createContext } from '../../fleet/fleet';
import { alwaysVisible } from '../../fleet/link';
import { simulatorHandlers } from '../../fleet/msw';
import { jsonResponse, type Simulator } from '../../fleet/sim';
import { advance, FaultGate, faultHarness, within, type Fault } from '../../fleet/faults.test-util';
import { XtoolSession } from './session';
import { XtoolSimulator } from './sim/simulator';

/**
 * Issue 15 for the xTool: no verdict from a failed request, silence is a fault, and the laser is
 * back within 5 s of the fault ending, without a reload; another laser is not affected.
 */

const { server, cleanup } = faultHarness();
let seq = 0;

function setup(served?: (sim: XtoolSimulator) => Simulator) {
  const id = `fault-laser-${++seq}`;
  const sim = new XtoolSimulator({ id, name: 'Laser' });
  const gate = new FaultGate(served ? served(sim) : sim);
  server.use(...simulatorHandlers(id, gate));
  const ctx = createContext(
    { id, name: 'Laser', kind: 'xtool', simulated: true },
    { visibility: alwaysVisible },
  );
  const session = new XtoolSession(ctx);
  cleanup.push(() => {
    session.stop();
    gate.dispose();
  });
  return { sim, gate, ctx, session, link: () => ctx.snapshot.getState().link };
}

const FAILED_REQUESTS: Fault[] = ['gateway', 'gateway-body', 'network', 'cut'];

describe('xTool: no verdict from a failed request', () => {
  it.each(FAILED_REQUESTS)(
    'identity requests that fail (%s) are a link problem, never "unsupported"; back within 5 s',
    async (fault) => {
      vi.spyOn(Math, 'random').mockReturnValue(0.999);
      const { gate, ctx, session, link } = setup();
      gate.fault = fault;
      session.start();
      await advance(12_000);
      const snap = ctx.snapshot.getState();
      expect(['reconnecting', 'offline']).toContain(snap.link);
      expect(snap.problem?.message).not.toMatch(/Unsupported/);
      expect(snap.problem?.kind).not.toBe('protocol');
      expect(session.detail.getState().model.family).toBe('unknown');
      // It keeps trying on its own.
      const tries = gate.seen.length;
      await advance(8000);
      expect(gate.seen.length).toBeGreaterThan(tries);

      gate.fault = 'none';
      await within(() => link() === 'online', 5000);
      expect(session.detail.getState().model.family).toBe('d-series');
    },
  );

  it('unreachable for 20 s while online (the gateway answers 502): back within 5 s, never unsupported', async () => {
    // The longest delays the backoff's jitter allows: a retry cannot land right after the fault by luck.
    vi.spyOn(Math, 'random').mockReturnValue(0.999);
    const { gate, ctx, session, link } = setup();
    session.start();
    await within(() => link() === 'online', 5000);
    gate.fault = 'gateway';
    await within(() => link() !== 'online', 5000);
    const seen: string[] = [];
    const unsub = ctx.snapshot.subscribe((s) => seen.push(s.problem?.message ?? ''));
    await advance(20_000);
    unsub();
    expect(seen.some((m) => /Unsupported/.test(m))).toBe(false);
    expect(ctx.snapshot.getState().problem?.message).toMatch(/cannot reach the controller/);
    gate.fault = 'none';
    await within(() => link() === 'online', 5000);
  });

  it('answers cut after 20 bytes are failed requests (not a protocol error); back within 5 s', async () => {
    const { gate, ctx, session, link } = setup();
    session.start();
    await within(() => link() === 'online', 5000);
    gate.fault = 'cut';
    await within(() => link() === 'offline' || link() === 'reconnecting', 5000);
    expect(ctx.snapshot.getState().problem?.message).toMatch(/cut off/);
    await advance(10_000);
    expect(ctx.snapshot.getState().link).not.toBe('protocol-error');
    gate.fault = 'none';
    await within(() => link() === 'online', 5000);
  });

  it('a whole answer of another shape is a protocol error naming the path (still retried)', async () => {
    let broken = false;
    const { gate, ctx, session, link } = setup((sim) => ({
      kind: 'xtool',
      fetch: (req, path) =>
        broken && path === '/progress'
          ? Promise.resolve(jsonResponse({ progress: 'lots', working: 0 }, 200, null))
          : sim.fetch(req, path),
      socket: (p, s) => sim.socket(p, s),
      dispose: () => sim.dispose(),
    }));
    session.start();
    await within(() => link() === 'online', 5000);
    broken = true;
    await within(() => link() === 'protocol-error', 5000);
    expect(ctx.snapshot.getState().problem).toMatchObject({ kind: 'protocol', path: 'progress' });
    // The working state still answers: that does not make the link good while /progress is not.
    const states = new Set<string>();
    const unsub = ctx.snapshot.subscribe((st) => states.add(st.link));
    await advance(10_000);
    unsub();
    expect([...states]).toEqual(['protocol-error']);
    broken = false;
    await within(() => link() === 'online', 5000);
    expect(gate.seen.length).toBeGreaterThan(0);
  });

  it('a device that said, whole, it is another model is asked again, and is back once it is a D-series', async () => {
    let other = true;
    const { ctx, session, link } = setup((sim) => ({
      kind: 'xtool',
      fetch: (req, path) =>
        other && path.startsWith('/getmachinetype')
          ? Promise.resolve(jsonResponse({ result: 'ok', type: 'xTool S1' }, 200, null))
          : sim.fetch(req, path),
      socket: (p, s) => sim.socket(p, s),
      dispose: () => sim.dispose(),
    }));
    session.start();
    await within(() => session.detail.getState().model.family === 'unsupported', 5000);
    expect(link()).toBe('protocol-error');
    expect(ctx.snapshot.getState().retryAt).not.toBeNull();
    other = false;
    await within(() => link() === 'online', 65_000);
    expect(session.detail.getState().model.family).toBe('d-series');
  });
});

describe('xTool: silence is a fault', () => {
  it('a silent link (requests accepted, nothing answered) is down within 5 s, back within 5 s', async () => {
    const { gate, ctx, session, link } = setup();
    session.start();
    await within(() => link() === 'online' && session.detail.getState().socketOpen, 5000);
    gate.fault = 'silent';
    await within(() => link() !== 'online', 5000);
    expect(ctx.snapshot.getState().problem?.kind).toBe('timeout');
    await advance(10_000);
    expect(link()).not.toBe('online');
    gate.fault = 'none';
    await within(() => link() === 'online', 5000);
  });

  it('another laser keeps updating while one is unreachable', async () => {
    const a = setup();
    const b = setup();
    a.session.start();
    b.session.start();
    await within(() => a.link() === 'online' && b.link() === 'online', 5000);
    a.gate.fault = 'silent';
    const before = b.ctx.snapshot.getState().updatedAt ?? 0;
    await advance(8000);
    expect(a.link()).not.toBe('online');
    expect(b.link()).toBe('online');
    expect(b.ctx.snapshot.getState().updatedAt ?? 0).toBeGreaterThan(before + 4000);
  });
});

/** The simulator behind a slow link: every request waits `each` ms on its way there and back. */
function slowLink(sim: XtoolSimulator, latency: { each: number }): Simulator {
  const wait = (ms: number) => new Promise((r) => setTimeout(r, ms));
  return {
    kind: 'xtool',
    fetch: async (req, path) => {
      const ms = latency.each;
      if (ms > 0) await wait(ms);
      const res = await sim.fetch(req, path);
      if (ms > 0) await wait(ms);
      return res;
    },
    socket: (p, s) => sim.socket(p, s),
    dispose: () => sim.dispose(),
  };
}

describe('xTool: a slow link that still delivers is ridden through', () => {
  it.each([
    // The fault matrix: 2 s each way, a request takes 4 s.
    { each: 2000, firstDataMs: 10_000 },
    // 2 s each way and a new TCP connection per request (the gateway's keep-alive is off): 8 s.
    { each: 4000, firstDataMs: 14_000 },
  ])(
    '$each ms each way, set right after a poll: fresh data within $firstDataMs ms, then never down while answers arrive',
    async ({ each, firstDataMs }) => {
      const latency = { each: 0 };
      const { ctx, session, link } = setup((sim) => slowLink(sim, latency));
      session.start();
      await within(() => link() === 'online' && session.detail.getState().socketOpen, 5000);
      // The worst moment: a poll has just been applied, the next starts a whole period later.
      const last = ctx.snapshot.getState().updatedAt ?? 0;
      await within(() => (ctx.snapshot.getState().updatedAt ?? 0) > last, 5000);
      latency.each = each;
      const t0 = Date.now();
      const through = t0 + 2 * each;
      const fresh = () => {
        const s = ctx.snapshot.getState();
        return s.link === 'online' && (s.updatedAt ?? 0) > through;
      };
      await within(fresh, firstDataMs);
      // From then on the answers keep coming: the link is never shown as down.
      const states = new Set<string>();
      const unsub = ctx.snapshot.subscribe((s) => states.add(s.link));
      const before = ctx.snapshot.getState().updatedAt ?? 0;
      await advance(30_000);
      unsub();
      expect([...states]).toEqual(['online']);
      expect(ctx.snapshot.getState().updatedAt ?? 0).toBeGreaterThan(before + 20_000);
      expect(ctx.snapshot.getState().problem).toBeNull();
      // Back to a fast link: still online, and a silence is again seen within 5 s.
      latency.each = 0;
      await advance(10_000);
      expect(link()).toBe('online');
    },
  );

  it('a silence right after a slow period is still detected, within the slow answers window', async () => {
    const latency = { each: 2000 };
    const { gate, session, link } = setup((sim) => slowLink(sim, latency));
    session.start();
    await within(() => link() === 'online', 60_000);
    await advance(12_000);
    expect(link()).toBe('online');
    gate.fault = 'silent';
    await within(() => link() !== 'online', 8000);
    gate.fault = 'none';
    await within(() => link() === 'online', 10_000);
  });
});

/** A browser's XMLHttpRequest that uploads for `ms`, reporting progress every 500 ms, then "ok". */
function slowUploadXhr(ms: number) {
  return class {
    status = 0;
    responseText = '';
    timeout = 0;
    upload: { onprogress: ((e: { loaded: number; total: number }) => void) | null } = { onprogress: null };
    onload: (() => void) | null = null;
    onerror: (() => void) | null = null;
    ontimeout: (() => void) | null = null;
    onabort: (() => void) | null = null;
    open(): void {}
    setRequestHeader(): void {}
    getAllResponseHeaders(): string {
      return 'content-type: application/json';
    }
    abort(): void {
      this.onabort?.();
    }
    send(): void {
      for (let t = 500; t < ms; t += 500)
        setTimeout(() => this.upload.onprogress?.({ loaded: t, total: ms }), t);
      setTimeout(() => {
        this.status = 200;
        this.responseText = '{"result":"ok"}';
        this.onload?.();
      }, ms);
    }
  };
}

describe('xTool: a long upload is not silence', () => {
  it('while an upload is under way (and the polls wait behind it), the link stays online', async () => {
    const { gate, session, link } = setup();
    session.start();
    await within(() => link() === 'online', 5000);
    vi.stubGlobal('XMLHttpRequest', slowUploadXhr(12_000));
    cleanup.push(() => vi.unstubAllGlobals());
    const states = new Set<string>();
    const unsub = session.ctx.snapshot.subscribe((s) => states.add(s.link));
    const done = session.client.upload(new Blob(['G0 X1\n']), { kind: 'job' }, 'upload-1');
    await advance(13_000);
    await expect(done).resolves.toBe('ok');
    unsub();
    expect([...states].filter((s) => s !== 'online')).toEqual([]);
    // The upload's 12 s are not an answer time: a silence right after it is seen within 5 s.
    gate.fault = 'silent';
    await within(() => link() !== 'online', 5000);
  });
});
