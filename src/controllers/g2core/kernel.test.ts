import { setupServer } from 'msw/node';
import { afterAll, afterEach, beforeAll, beforeEach, describe, expect, it, vi } from 'vitest';
import { LinkError } from '../../fleet/errors';
import { createContext } from '../../fleet/fleet';
import { alwaysVisible } from '../../fleet/link';
import { simulatorHandlers } from '../../fleet/msw';
import { G2coreSession, SR_POLL_MS } from './session';
import { G2coreSimulator } from './sim/simulator';
import { job, operation, type Job, type Operation, type SrValues } from './wire';

/**
 * The g2core session on the session kernel (issue 12), with fake timers: nothing is written
 * after stop, a command kicks the poll in flight, an unchanged answer notifies nobody, a lost
 * link is retried. (The family has no socket: the REST design has none, so no heartbeat.)
 */

let sim: G2coreSimulator;
const server = setupServer();

beforeAll(() => server.listen({ onUnhandledRequest: 'error' }));
afterAll(() => server.close());
beforeEach(() => {
  vi.useFakeTimers();
  sim = new G2coreSimulator({ id: 'cnc', name: 'CNC' });
  server.resetHandlers(...simulatorHandlers('cnc', sim));
});
afterEach(() => {
  vi.restoreAllMocks();
  sim.dispose();
  vi.useRealTimers();
});

function makeSession(): G2coreSession {
  const ctx = createContext(
    { id: 'cnc', name: 'CNC', kind: 'g2core', simulated: true },
    { visibility: alwaysVisible, principal: () => ({ name: 'tester', role: 'supervisor' }) },
  );
  const s = new G2coreSession(ctx);
  s.start();
  return s;
}

const settle = (ms = 600) => vi.advanceTimersByTimeAsync(ms);

/** An answer the test hands over by hand, whenever it likes (even after stop). */
function held<T>() {
  const waiting: Array<(v: T) => void> = [];
  return {
    /** A request whose answer is on its way: it ignores the abort, as a reply already sent would. */
    next: () => new Promise<T>((resolve) => waiting.push(resolve)),
    get count() {
      return waiting.length;
    },
    answerAll: (v: T) => waiting.splice(0).forEach((r) => r(v)),
  };
}

describe('g2core on the session kernel', () => {
  it('writes nothing after stop: a status report, a job list and an operation answered late change no store', async () => {
    const s = makeSession();
    await settle();
    await s.ctx.commands.run(s.jog, { axis: 'x', distance: 100, feed: 600 });
    await settle(300);
    const opId = Object.keys(s.detail.getState().ops)[0]!;
    expect(opId).toBeTruthy();

    const status = held<SrValues>();
    const jobs = held<Job[]>();
    const ops = held<Operation>();
    const sr = vi.spyOn(s.client, 'statusReport').mockImplementation(status.next);
    const jl = vi.spyOn(s.client, 'jobs').mockImplementation(jobs.next);
    const op = vi.spyOn(s.client, 'operation').mockImplementation(ops.next);
    // A status poll and a slow poll (job list + the jog's operation) are now on their way.
    await settle(SR_POLL_MS + 1000);
    expect(status.count).toBe(1);
    expect(jobs.count).toBe(1);
    expect(ops.count).toBe(1);

    const detail = s.detail.getState();
    const snapshot = s.ctx.snapshot.getState();
    const settings = s.settings.getState();
    const logged = s.ctx.log.store.getState().entries.length;
    s.stop();

    // The answers arrive after stop, each saying something new.
    status.answerAll({ stat: 2, posx: 123, posy: 45 });
    jobs.answerAll([
      job.parse({ id: 7, name: 'late.nc', state: 'error', lines: 3, done: 1, error: { code: 131 } }),
    ]);
    ops.answerAll(operation.parse({ id: opId, opstate: 'error', error: { code: 220 } }));
    await settle(5000);

    expect(s.detail.getState()).toBe(detail);
    expect(s.ctx.snapshot.getState()).toBe(snapshot);
    expect(s.settings.getState()).toBe(settings);
    expect(s.ctx.log.store.getState().entries.length).toBe(logged);
    // And no poll after stop.
    expect([sr.mock.calls.length, jl.mock.calls.length, op.mock.calls.length]).toEqual([1, 1, 1]);
  });

  it('a command answered after stop tracks nothing', async () => {
    const s = makeSession();
    await settle();
    const answer = held<string>();
    vi.spyOn(s.client, 'runOperation').mockImplementation(answer.next);
    const sent = s.ctx.commands.run(s.mdi, { text: 'G0 X5' });
    await settle(0);
    expect(answer.count).toBe(1);
    const entries = s.detail.getState().console;
    s.stop();
    answer.answerAll('77');
    await sent;
    await settle(1000);
    expect(s.detail.getState().ops['77']).toBeUndefined();
    expect(s.detail.getState().console).toBe(entries); // still "sent", no operation id written
  });

  it('a command kicks the status poll: polled again right after the poll in flight, not an interval later', async () => {
    const s = makeSession();
    await settle();
    const real = s.client.statusReport.bind(s.client);
    const first = held<SrValues>();
    let calls = 0;
    vi.spyOn(s.client, 'statusReport').mockImplementation((filter, signal) => {
      calls++;
      return calls === 1 ? first.next() : real(filter, signal);
    });
    await settle(SR_POLL_MS);
    expect(first.count).toBe(1); // a status poll is in flight
    // The override is set while that poll is on its way (it may have read the old factor).
    await s.ctx.commands.run(s.setOverride, { key: 'mfo', value: 1.5 });
    first.answerAll({});
    await settle(5);
    expect(calls).toBe(2); // at once after the poll in flight, not SR_POLL_MS later
    await settle(20);
    expect(s.detail.getState().sr.mfo).toBe(1.5);
    s.stop();
  });

  it('an unchanged status report notifies nobody: parts keep their identity (no JSON comparison)', async () => {
    const s = makeSession();
    await settle();
    const detail = s.detail.getState();
    const positions = s.ctx.snapshot.getState().positions;
    const alarms = s.ctx.snapshot.getState().alarms;
    const listener = vi.fn();
    const unsubscribe = s.detail.subscribe(listener);
    // The same values again, as new objects (a full report answers every key).
    vi.spyOn(s.client, 'statusReport').mockImplementation(async () => ({ ...detail.sr }));
    await settle(SR_POLL_MS * 4);
    expect(listener).not.toHaveBeenCalled();
    expect(s.detail.getState()).toBe(detail);
    expect(s.ctx.snapshot.getState().positions).toBe(positions);
    expect(s.ctx.snapshot.getState().alarms).toBe(alarms);
    unsubscribe();
    s.stop();
  });

  it('a lost link is retried with backoff and comes back online; a failed job list does not fail it', async () => {
    const s = makeSession();
    await settle();
    const links = new Set<string>();
    const unsubscribe = s.ctx.snapshot.subscribe((snap) => links.add(snap.link));
    const jobs = vi
      .spyOn(s.client, 'jobs')
      .mockRejectedValue(new LinkError('http', 'HTTP 500', { status: 500 }));
    await settle(2500);
    expect(jobs.mock.calls.length).toBeGreaterThanOrEqual(2);
    expect([...links]).toEqual(['online']); // never flapped: whether the controller answers is the status poll's to say
    unsubscribe();
    const sr = vi.spyOn(s.client, 'statusReport').mockRejectedValue(new LinkError('network', 'unreachable'));
    await settle(SR_POLL_MS + 10);
    expect(s.ctx.snapshot.getState().link).toBe('reconnecting');
    sr.mockRestore();
    await settle(3000);
    expect(s.ctx.snapshot.getState().link).toBe('online');
    s.stop();
  });
});
