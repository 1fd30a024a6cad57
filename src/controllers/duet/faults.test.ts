import { describe, expect, it, vi } from 'vitest';
import { createContext } from '../../fleet/fleet';
import { alwaysVisible } from '../../fleet/link';
import { simulatorHandlers } from '../../fleet/msw';
import { FuzzSimulator } from '../../../tests/faults/fuzz';
import { LinkError } from '../../fleet/errors';
import { AUTH_RETRY_BASE_MS, AUTH_RETRY_MAX_MS, fromGateway, isLinkFault } from '../../fleet/faults';
import { advance, FaultGate, faultHarness, within, type Fault } from '../../fleet/faults.test-util';
import type { Simulator } from '../../fleet/sim';
import { DuetClient, isAuthError, parseDuetError } from './client';
import { DuetSession, PASSWORD_REFUSED, RESYNC_EVERY_MS } from './session';
import { DuetSimulator } from './sim/simulator';
// A connect answer DSF cannot have sent (the 'cut' fault) makes the client try a standalone board,
// whose client is a dynamic import. Loaded here first: under fake timers a first import (read and
// transformed from disk in real time) may not finish while the clock is advanced, and the test
// then depended on whether another file in the same worker had loaded it before.
import './rrf-client';

/**
 * Issue 15 for the Duet: failed requests are link problems (never "Incompatible DCS version" nor
 * "needs login"), refused credentials that are the gateway's are tried again on their own,
 * slowly, a typed password never is, a silent link is down within 5 s, and the machine is back
 * within 5 s of the fault ending. (In msw the page holds the DSF key; through the gateway it never
 * does — gateway.test.ts.)
 */

const { server, cleanup } = faultHarness();
let seq = 0;

function setup() {
  const id = `fault-duet-${++seq}`;
  const sim = new DuetSimulator({ id, name: 'duet-sim', now: () => Date.now(), tickMs: 250 });
  const gate = new FaultGate(sim);
  server.use(...simulatorHandlers(id, gate));
  const ctx = createContext(
    { id, name: 'Duet', kind: 'duet', simulated: true },
    { visibility: alwaysVisible, principal: () => ({ name: 'tester', role: 'supervisor' }) },
  );
  const session = new DuetSession(ctx);
  cleanup.push(() => {
    session.stop();
    gate.dispose();
  });
  const connects = () => gate.seen.filter((p) => p === '/machine/connect').length;
  return { sim, gate, ctx, session, connects, link: () => ctx.snapshot.getState().link };
}

describe('Duet: no verdict from a failed request', () => {
  it('the console server\'s own 502 is not DSF\'s "Incompatible DCS version"', () => {
    const own = parseDuetError(502, { error: 'cannot reach the controller', gateway: true }, '');
    expect(own?.message).toBe('cannot reach the controller');
    expect(own?.kind).toBe('network');
    expect(parseDuetError(502, null, '')?.message).toMatch(/Incompatible DCS version/);
  });

  it.each<Fault>(['gateway', 'gateway-body', 'network', 'cut'])(
    'connect fails (%s): a link problem, retried quickly; back within 5 s',
    async (fault) => {
      vi.spyOn(Math, 'random').mockReturnValue(0.999);
      const { gate, ctx, session, link } = setup();
      gate.fault = fault;
      session.start();
      await advance(20_000);
      const snap = ctx.snapshot.getState();
      expect(['reconnecting', 'offline']).toContain(snap.link);
      expect(snap.problem?.message).not.toMatch(/DCS|Needs login/);
      expect(snap.problem?.kind).not.toBe('protocol');
      gate.fault = 'none';
      await within(() => link() === 'online', 5000);
    },
  );

  it('the console server\'s own 403 (a refusal, not DSF\'s) is not "needs login"', async () => {
    const { gate, ctx, session, link } = setup();
    gate.body401 = { status: 403, body: JSON.stringify({ error: 'viewers may not do this', gateway: true }) };
    gate.fault = 'unauthorized';
    session.start();
    await within(() => link() === 'reconnecting' || link() === 'offline', 5000);
    expect(link()).not.toBe('needs-login');
    expect(ctx.snapshot.getState().problem?.message).toMatch(/viewers may not/);
    gate.fault = 'none';
    await within(() => link() === 'online', 5000);
  });
});

/** A stand-in for the console server that answers every request of machine `id` with `answer()`. */
function answering(id: string, answer: () => Response): DuetClient {
  const sim: Simulator = { kind: 'duet', fetch: () => Promise.resolve(answer()), dispose: () => undefined };
  server.use(...simulatorHandlers(id, sim));
  return new DuetClient(id);
}

async function failure(p: Promise<unknown>): Promise<LinkError> {
  const e = await p.then(
    () => null,
    (x: unknown) => x,
  );
  if (!(e instanceof LinkError)) throw new Error(`expected a LinkError, got ${String(e)}`);
  return e;
}

describe("Duet: the console server's own answers are never DSF's", () => {
  const json = (body: unknown, status: number, headers: Record<string, string> = {}) =>
    new Response(JSON.stringify(body), {
      status,
      headers: { 'Content-Type': 'application/json', ...headers },
    });

  it('its 502 with the X-Shopdeck-Gateway header, whatever the body: a link fault in its words', async () => {
    for (const answer of [
      () => new Response('Bad Gateway', { status: 502, headers: { 'X-Shopdeck-Gateway': 'error' } }),
      () => new Response('', { status: 502, headers: { 'X-Shopdeck-Gateway': 'error' } }),
      () =>
        json({ error: 'cannot reach the controller', gateway: true }, 502, { 'X-Shopdeck-Gateway': 'error' }),
      () => json({ error: 'cannot reach the controller', gateway: true }, 502),
    ]) {
      const client = answering(`gw502-${++seq}`, answer);
      for (const call of [
        () => client.code('M115'),
        () => client.modelRaw(),
        () => client.noop(),
        () => client.connect(),
      ]) {
        const e = await failure(call());
        expect(e.message).not.toMatch(/DCS|Incompatible/);
        expect(fromGateway(e)).toBe(true);
        expect(isLinkFault(e)).toBe(true);
        expect(e.kind).not.toBe('vendor');
        expect(isAuthError(e)).toBe(false);
      }
    }
  });

  it('its 401/403 refusal is not a DSF session that expired', async () => {
    const client = answering(`gw403-${++seq}`, () =>
      json({ error: 'viewers may not do this', gateway: true }, 403),
    );
    const e = await failure(client.code('M25'));
    expect(e.message).toBe('viewers may not do this');
    expect(fromGateway(e)).toBe(true);
    expect(isAuthError(e)).toBe(false);
  });

  it("DSF's own 502 (no mark of the console server) keeps DSF's words, and is still a link fault", async () => {
    const client = answering(
      `dsf502-${++seq}`,
      () => new Response('Incompatible DCS version', { status: 502 }),
    );
    const e = await failure(client.code('M115'));
    expect(e.message).toMatch(/Incompatible DCS version/);
    expect(fromGateway(e)).toBe(false);
    expect(isLinkFault(e)).toBe(true);
  });
});

describe('Duet: bad data on WS /machine', () => {
  function fuzzSetup() {
    const id = `bad-data-duet-${++seq}`;
    const duet = new DuetSimulator({ id, name: 'duet-sim', now: () => Date.now(), tickMs: 250 });
    const sim = new FuzzSimulator(duet);
    let opened = 0;
    const socket = sim.socket.bind(sim);
    sim.socket = (p, sock) => {
      opened++;
      return socket(p, sock);
    };
    server.use(...simulatorHandlers(id, sim));
    const ctx = createContext(
      { id, name: 'Duet', kind: 'duet', simulated: true },
      { visibility: alwaysVisible, principal: () => ({ name: 'tester', role: 'supervisor' }) },
    );
    const session = new DuetSession(ctx);
    cleanup.push(() => {
      session.stop();
      sim.dispose();
    });
    const errors = () =>
      ctx.log.store
        .getState()
        .entries.filter((e) => e.level === 'error')
        .map((e) => e.text);
    // Every link state and problem shown (a protocol error may last only until the next patch).
    const shown: Array<{ link: string; problem: string }> = [];
    cleanup.push(
      ctx.snapshot.subscribe((s) => shown.push({ link: s.link, problem: s.problem?.message ?? '' })),
    );
    const since = (from: number) => shown.slice(from);
    return {
      sim,
      duet,
      ctx,
      session,
      opened: () => opened,
      errors,
      shown,
      since,
      link: () => ctx.snapshot.getState().link,
    };
  }

  it('a patch that breaks the model is shown and logged, dropped, and the model read again by a new socket', async () => {
    const { sim, session, opened, errors, shown, since, link } = fuzzSetup();
    session.start();
    await within(() => link() === 'online' && sim.socketsOpen === 1, 5000);
    const heat = session.store.getState().model?.heat;
    expect(heat).toBeDefined();
    const sockets = opened();
    const mark = shown.length;
    sim.sendFrame('{"heat":"not a heat object"}');
    await within(() => since(mark).some((s) => s.link === 'protocol-error'), 500);
    const err = since(mark).find((s) => s.link === 'protocol-error');
    expect(err?.problem).toMatch(/at "heat".*dropped; the object model is read again/);
    expect(errors().some((t) => /Protocol error: .*heat/.test(t))).toBe(true);
    // The last valid model stays on screen; the session is not recreated or stopped.
    expect(session.store.getState().model?.heat).toBe(heat);
    await within(() => opened() > sockets, 1000);
    await within(() => link() === 'online', 3000);
    expect(session.started).toBe(true);
  });

  it('the console server refusing a frame of the Duet (close 1007) is a protocol error; the socket reconnects', async () => {
    const { sim, duet, session, opened, since, shown, link } = fuzzSetup();
    session.start();
    await within(() => link() === 'online' && sim.socketsOpen === 1, 5000);
    const mark = shown.length;
    duet.closeSockets(1007, 'the controller sent a patch that does not apply');
    await within(() => since(mark).some((s) => s.link === 'protocol-error'), 500);
    expect(since(mark).find((s) => s.link === 'protocol-error')?.problem).toMatch(
      /data the console cannot use: the controller sent a patch that does not apply/,
    );
    await within(() => opened() === 2 && link() === 'online', 5000);
    expect(session.started).toBe(true);
  });

  it('bad frames again soon after: shown each time, but the socket is renewed at most every RESYNC_EVERY_MS', async () => {
    const { sim, session, opened, since, shown, link } = fuzzSetup();
    const errorSince = (mark: number) => since(mark).some((s) => s.link === 'protocol-error');
    session.start();
    await within(() => link() === 'online' && sim.socketsOpen === 1, 5000);
    sim.sendFrame('{"state":5}');
    await within(() => opened() === 2 && link() === 'online', 3000);
    const renewedAt = Date.now();
    let mark = shown.length;
    sim.sendFrame('not JSON at all');
    await within(() => errorSince(mark), 500);
    await within(() => link() === 'online', 2000);
    mark = shown.length;
    sim.sendFrame('[1,2,3]');
    await within(() => errorSince(mark), 500);
    await advance(RESYNC_EVERY_MS - (Date.now() - renewedAt) - 500);
    expect(opened()).toBe(2);
    await within(() => opened() === 3, 1500);
    await within(() => link() === 'online', 3000);
  });
});

describe('Duet: refused credentials', () => {
  it('the machine password changed, then changed back: back online by itself', async () => {
    const { sim, ctx, session, link } = setup();
    session.start();
    await within(() => link() === 'online', 5000);
    // The password is changed on the Duet: the session goes, the socket is refused.
    sim.password = 'changed';
    sim.expireSessions();
    sim.closeSockets(4000, 'simulated socket close');
    await within(() => link() === 'needs-login', 15_000);
    const snap = ctx.snapshot.getState();
    expect(snap.problem?.message).toBe(PASSWORD_REFUSED);
    expect(snap.problem?.message).toMatch(/machines file/);
    expect(snap.retryAt).not.toBeNull();
    await advance(5000);
    sim.password = null;
    await within(() => link() === 'online', 10_000);
  });

  it('a password that stays wrong is tried a few times quickly, then at most once a minute', async () => {
    vi.spyOn(Math, 'random').mockReturnValue(0);
    const { sim, session, connects, link } = setup();
    sim.password = 'secret';
    session.start();
    await within(() => link() === 'needs-login', 5000);
    const times: number[] = [];
    let last = connects();
    for (let t = 0; t < 15 * 60_000; t += 250) {
      await vi.advanceTimersByTimeAsync(250);
      const n = connects();
      if (n !== last) times.push(Date.now());
      last = n;
    }
    const gaps = times.slice(1).map((t, i) => t - (times[i] ?? 0));
    expect(times.length).toBeGreaterThan(10);
    expect(times.length).toBeLessThan(30);
    // The first tries 2.5 s apart: credentials right again after a few seconds are back within 5 s.
    expect(gaps.slice(0, 3).every((g) => g <= AUTH_RETRY_BASE_MS + 500)).toBe(true);
    expect(gaps.slice(-8).every((g) => g >= AUTH_RETRY_MAX_MS * 0.8 - 1000)).toBe(true);
    expect(gaps.every((g) => g <= AUTH_RETRY_MAX_MS + 1000)).toBe(true);
    expect(link()).toBe('needs-login');
    sim.password = null;
    await within(() => link() === 'online', AUTH_RETRY_MAX_MS + 2000);
  });

  it('a password typed into the login form that is refused is never tried again on its own', async () => {
    const { sim, session, connects, link } = setup();
    sim.password = 'secret';
    session.start();
    await within(() => link() === 'needs-login', 5000);
    await expect(session.login({ password: 'nope' })).rejects.toThrow(/refused/);
    const tried = connects();
    await advance(5 * 60_000);
    expect(connects()).toBe(tried);
    expect(link()).toBe('needs-login');
  });
});

describe('Duet: silence', () => {
  it('a silent link (socket and HTTP) is down within 5 s and back within 5 s', async () => {
    const { gate, session, link } = setup();
    session.start();
    await within(() => link() === 'online', 5000);
    gate.fault = 'silent';
    await within(() => link() !== 'online', 5000);
    await advance(12_000);
    expect(link()).not.toBe('online');
    gate.fault = 'none';
    await within(() => link() === 'online', 5000);
  });

  it.each<Fault>(['silent', 'cut', 'gateway'])(
    'while the model is polled (no socket): a %s link is down within 5 s and back within 5 s',
    async (fault) => {
      const { sim, gate, session, link } = setup();
      sim.refuseSockets = true;
      session.start();
      await within(() => link() === 'online' && session.store.getState().transport === 'polling', 15_000);
      await advance(1000);
      expect(link()).toBe('online');
      gate.fault = fault;
      await within(() => link() !== 'online', 5000);
      await advance(6000);
      expect(link()).not.toBe('online');
      gate.fault = 'none';
      await within(() => link() === 'online', 5000);
    },
  );

  it('another Duet keeps updating meanwhile', async () => {
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
