import { afterEach, beforeEach, describe, expect, it, vi } from 'vitest';
import type { SessionContext } from '../../fleet/contract';
import { LinkError } from '../../fleet/errors';
import { createContext } from '../../fleet/fleet';
import { alwaysVisible } from '../../fleet/link';
import { TouchcutSession } from './session';
import { setTouchcutUnits } from './state';
import { machineInfoSchema, monitorSchema, statusSchema, type HeldLoginWire, type Status } from './wire';

/**
 * The TouchCut session on the kernel, with its client stubbed so the test decides when each
 * answer arrives: nothing is written after stop, a change while a poll is in flight polls again
 * right after it, equal answers keep their identity.
 */

function deferred<T>() {
  let resolve!: (v: T) => void;
  let reject!: (e: unknown) => void;
  const promise = new Promise<T>((res, rej) => {
    resolve = res;
    reject = rej;
  });
  return { promise, resolve, reject };
}

type Pending<T> = Array<ReturnType<typeof deferred<T>> & { args: unknown[] }>;

/** Makes `method` of the session's client answer only when the test says so. */
function hold<T>(
  session: TouchcutSession,
  method: 'status' | 'machineInfo' | 'monitor' | 'screenshot' | 'login' | 'stats' | 'loginState',
) {
  const pending: Pending<T> = [];
  vi.spyOn(session.client, method).mockImplementation(((...args: unknown[]) => {
    const d = deferred<T>();
    pending.push({ ...d, args });
    return d.promise;
  }) as never);
  return pending;
}

const STATUS: Status = statusSchema.parse({
  machineState: 'Running',
  programName: 'bracket.nc',
  programProgress: 40,
  msgStatus: [{ key: 'collision', msg: 'Torch collision detected' }],
});
const INFO = machineInfoSchema.parse({ exeName: 'TouchCut7.exe', exeVersion: '7.0.123', licensedTo: 'Acme' });
const MONITOR = monitorSchema.parse({ io: { din: [], dout: [], ain: [], aout: [] }, axes: [] });
/** The gateway's answer to a login: who, until when; never a token. */
const HELD: HeldLoginWire = { loggedIn: true, user: 'operator' };
const PNG = new Blob([new Uint8Array([0x89, 0x50, 0x4e, 0x47])], { type: 'image/png' });

let ctx: SessionContext;
let session: TouchcutSession;

beforeEach(() => {
  vi.useFakeTimers();
  setTouchcutUnits('default');
  ctx = createContext(
    { id: 'tcl', name: 'Plasma', kind: 'touchcut', simulated: true },
    { visibility: alwaysVisible, principal: () => ({ name: 'sam', role: 'operator' }) },
  );
  session = new TouchcutSession(ctx);
  // Who the gateway is logged in as: never answered unless a test says so.
  hold<HeldLoginWire>(session, 'loginState');
});
afterEach(() => {
  session.stop();
  vi.restoreAllMocks();
  vi.useRealTimers();
});

/** Every store a TouchCut view reads, and the log. */
function everything() {
  return {
    snapshot: ctx.snapshot.getState(),
    session: session.store.getState(),
    monitor: session.monitor.store.getState(),
    screenshot: session.screenshot.store.getState(),
    log: ctx.log.store.getState(),
  };
}

describe('touchcut session: nothing is written after stop', () => {
  it('answers to the status, machine-info, monitor and screenshot requests in flight at stop change no store', async () => {
    const status = hold<Status>(session, 'status');
    const info = hold<typeof INFO>(session, 'machineInfo');
    const monitor = hold<typeof MONITOR>(session, 'monitor');
    const screenshot = hold<{ blob: Blob; bytes: number }>(session, 'screenshot');
    session.start();
    session.monitor.setFields(['axes.*']);
    session.monitor.acquire();
    session.screenshot.subscribe();
    await vi.advanceTimersByTimeAsync(0);
    expect([status.length, info.length, monitor.length, screenshot.length]).toEqual([1, 1, 1, 1]);
    const signals = [status, info, monitor, screenshot].map((p) => p[0]?.args.at(-1) as AbortSignal);

    const before = everything();
    session.stop();
    expect(signals.every((s) => s.aborted)).toBe(true); // the requests are cancelled…
    status[0]?.resolve(STATUS); // …and an answer that comes anyway is dropped
    info[0]?.resolve(INFO);
    monitor[0]?.resolve(MONITOR);
    screenshot[0]?.resolve({ blob: PNG, bytes: 4 });
    await vi.advanceTimersByTimeAsync(10_000);

    const after = everything();
    expect(after.snapshot).toBe(before.snapshot);
    expect(after.session).toBe(before.session);
    expect(after.monitor).toBe(before.monitor);
    expect(after.screenshot).toBe(before.screenshot);
    expect(after.log).toBe(before.log);
    // …and nothing is asked after stop.
    expect([status.length, info.length, monitor.length, screenshot.length]).toEqual([1, 1, 1, 1]);
  });

  it('a 401 that arrives after stop does not log the session out or mark the machine "needs login"', async () => {
    const status = hold<Status>(session, 'status');
    const screenshot = hold<{ blob: Blob; bytes: number }>(session, 'screenshot');
    const stats = hold<unknown>(session, 'stats');
    session.store.setState({ auth: { mode: 'user', user: 'operator', expiresAt: null, reason: null } });
    session.start();
    session.screenshot.subscribe();
    const read = ctx.queries.fetch(
      session.stats.key(
        { startDate: '2026-03-09', endBeforeDate: '2026-03-16', condensed: false },
        'default',
      ),
      session.stats.read(
        { startDate: '2026-03-09', endBeforeDate: '2026-03-16', condensed: false },
        'default',
      ),
    );
    await vi.advanceTimersByTimeAsync(0);
    expect(stats).toHaveLength(1);
    const before = everything();
    session.stop();
    const unauthorized = new LinkError('http', 'HTTP 401', { status: 401 });
    status[0]?.reject(unauthorized);
    screenshot[0]?.reject(unauthorized);
    stats[0]?.reject(unauthorized);
    await expect(read).rejects.toBeTruthy();
    await vi.advanceTimersByTimeAsync(5000);
    expect(everything()).toEqual(before);
    expect(ctx.snapshot.getState()).toBe(before.snapshot);
    expect(session.loggedIn).toBe(true);
  });

  it('drops the answer of a run that ended, after stop and a new start', async () => {
    const status = hold<Status>(session, 'status');
    hold<typeof INFO>(session, 'machineInfo');
    session.start();
    await vi.advanceTimersByTimeAsync(0);
    session.stop();
    session.start();
    await vi.advanceTimersByTimeAsync(0);
    expect(status).toHaveLength(2);
    status[0]?.resolve(STATUS); // late answer of the first run
    await vi.advanceTimersByTimeAsync(0);
    expect(session.store.getState().status).toBeNull();
    expect(ctx.snapshot.getState().link).toBe('connecting');
    status[1]?.resolve(STATUS);
    await vi.advanceTimersByTimeAsync(0);
    expect(session.store.getState().status?.machineState).toBe('Running');
    expect(ctx.snapshot.getState().link).toBe('online');
  });

  it('a login answered after stop is forgotten, not written', async () => {
    hold<Status>(session, 'status');
    hold<typeof INFO>(session, 'machineInfo');
    const login = hold<HeldLoginWire>(session, 'login');
    session.start();
    const done = session.login({ username: 'operator', password: 'operator' });
    await vi.advanceTimersByTimeAsync(0);
    const before = everything();
    session.stop();
    login[0]?.resolve(HELD);
    await done;
    expect(everything()).toEqual(before);
    expect(session.store.getState().auth.mode).toBe('key');
    expect(session.loggedIn).toBe(false);
  });
});

describe('touchcut session: polls again right after a change (kick)', () => {
  it('a units change while a status poll is in flight reads the status again at once, in the new units', async () => {
    const status = hold<Status>(session, 'status');
    hold<typeof INFO>(session, 'machineInfo');
    session.start();
    await vi.advanceTimersByTimeAsync(0);
    expect(status).toHaveLength(1);
    expect(status[0]?.args[0]).toBe('default');
    setTouchcutUnits('imperial'); // the poll in flight asked in the old units
    status[0]?.resolve(STATUS);
    await vi.advanceTimersByTimeAsync(0);
    expect(status).toHaveLength(2); // right after it, not a second later
    expect(status[1]?.args[0]).toBe('imperial');
    status[1]?.resolve(STATUS);
    await vi.advanceTimersByTimeAsync(999);
    expect(status).toHaveLength(2); // then the interval again
    await vi.advanceTimersByTimeAsync(1);
    expect(status).toHaveLength(3);
  });

  it('a login after "needs login" polls at once; nothing is asked before the key may be retried', async () => {
    const status = hold<Status>(session, 'status');
    hold<typeof INFO>(session, 'machineInfo');
    const login = hold<HeldLoginWire>(session, 'login');
    session.start();
    await vi.advanceTimersByTimeAsync(0);
    status[0]?.reject(new LinkError('http', 'HTTP 401', { status: 401 }));
    await vi.advanceTimersByTimeAsync(0);
    expect(ctx.snapshot.getState().link).toBe('needs-login');
    // The refused key is the gateway's: tried again on its own, but not before its backoff (≥ 1.6 s).
    await vi.advanceTimersByTimeAsync(1000);
    expect(status).toHaveLength(1);
    const done = session.login({ username: 'operator', password: 'operator' });
    login[0]?.resolve(HELD);
    await done;
    await vi.advanceTimersByTimeAsync(0);
    expect(status).toHaveLength(2);
    status[1]?.resolve(STATUS);
    await vi.advanceTimersByTimeAsync(0);
    expect(ctx.snapshot.getState().link).toBe('online');
  });
});

describe('touchcut session: structural sharing', () => {
  it('an equal status keeps the identity of what a view reads (status, alarms, positions)', async () => {
    const status = hold<Status>(session, 'status');
    hold<typeof INFO>(session, 'machineInfo');
    session.start();
    await vi.advanceTimersByTimeAsync(0);
    status[0]?.resolve(statusSchema.parse(structuredClone(STATUS)));
    await vi.advanceTimersByTimeAsync(1000);
    const first = { status: session.store.getState().status, snap: ctx.snapshot.getState() };
    status[1]?.resolve(statusSchema.parse(structuredClone(STATUS)));
    await vi.advanceTimersByTimeAsync(0);
    expect(session.store.getState().status).toBe(first.status);
    expect(ctx.snapshot.getState().alarms).toBe(first.snap.alarms);
    expect(ctx.snapshot.getState().positions).toBe(first.snap.positions);
  });
});
