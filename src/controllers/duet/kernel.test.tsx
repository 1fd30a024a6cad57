// @vitest-environment happy-dom
import { act, cleanup, render } from '@testing-library/react';
import { afterEach, beforeEach, describe, expect, it, vi } from 'vitest';
import type { SessionContext } from '../../fleet/contract';
import { createContext } from '../../fleet/fleet';
import { useBlockedReason } from '../../fleet/kernel';
import { alwaysVisible } from '../../fleet/link';
import { useStoreSelect } from '../../fleet/react';
import type { JsonObject } from './patch';
import { DuetSession, POLL_AFTER_MS, POLL_EVERY_MS } from './session';
import { baseModel } from './sim/data/model';

/**
 * The Duet session on the session kernel (issue 12), with fake timers, a fake WebSocket and a
 * stubbed client, so every answer arrives exactly when the test says: nothing is written after
 * stop, a command is followed by a poll at once, the heartbeat (PING, no PONG) reconnects, a
 * button's availability follows the Duet store, and a patch re-renders only what it changed.
 */

class FakeSocket {
  static all: FakeSocket[] = [];
  readyState = 0;
  sent: string[] = [];
  closed = false;
  onopen: (() => void) | null = null;
  onmessage: ((ev: { data: unknown }) => void) | null = null;
  onclose: ((ev: { code: number; reason: string }) => void) | null = null;
  onerror: (() => void) | null = null;
  constructor(readonly url: string) {
    FakeSocket.all.push(this);
  }
  open(): void {
    this.readyState = 1;
    this.onopen?.();
  }
  frame(data: unknown): void {
    this.onmessage?.({ data: typeof data === 'string' ? data : JSON.stringify(data) });
  }
  /** The server closes it. */
  drop(code: number, reason = ''): void {
    this.readyState = 3;
    this.onclose?.({ code, reason });
  }
  send(d: string): void {
    this.sent.push(d);
  }
  close(): void {
    this.closed = true;
    this.readyState = 3;
  }
}

function deferred<T>() {
  let resolve!: (v: T) => void;
  let reject!: (e: Error) => void;
  const promise = new Promise<T>((res, rej) => {
    resolve = res;
    reject = rej;
  });
  return { promise, resolve, reject };
}

let ctx: SessionContext;
let session: DuetSession;
const model = (): JsonObject => baseModel('Duet kernel test');
const last = (): FakeSocket => {
  const s = FakeSocket.all.at(-1);
  if (!s) throw new Error('no socket');
  return s;
};

beforeEach(() => {
  vi.useFakeTimers();
  FakeSocket.all = [];
  vi.stubGlobal('WebSocket', FakeSocket);
  ctx = createContext(
    { id: 'dk', name: 'Duet', kind: 'duet', simulated: true },
    { visibility: alwaysVisible, principal: () => ({ name: 'op', role: 'supervisor' }) },
  );
  session = new DuetSession(ctx);
  vi.spyOn(session.client, 'connect').mockImplementation(async () => {
    session.client.connected = true;
    return null;
  });
  vi.spyOn(session.client, 'noop').mockResolvedValue(undefined);
  vi.spyOn(session.client, 'disconnect').mockResolvedValue(undefined);
});

afterEach(() => {
  cleanup();
  session.stop();
  vi.unstubAllGlobals();
  vi.useRealTimers();
});

/** Start, open the socket and deliver the full model: online. */
async function online(): Promise<FakeSocket> {
  session.start();
  await vi.advanceTimersByTimeAsync(0);
  const s = last();
  s.open();
  s.frame(model());
  expect(ctx.snapshot.getState().link).toBe('online');
  return s;
}

const heaterPatch = (current: number) => ({
  heat: { heaters: [{ current }, {}, null, {}] },
});

describe('Duet session: nothing is written after stop', () => {
  it('a socket frame that arrives after stop changes no store', async () => {
    const s = await online();
    const deliver = s.onmessage; // a frame already on its way when the session stops
    const before = { duet: session.store.getState(), snap: ctx.snapshot.getState() };
    session.stop();
    deliver?.({ data: JSON.stringify(heaterPatch(99)) });
    deliver?.({ data: JSON.stringify({ state: { status: 'halted' } }) });
    expect(session.store.getState()).toBe(before.duet);
    expect(ctx.snapshot.getState()).toBe(before.snap);
    expect(s.closed).toBe(true);
  });

  it('a connect answer after stop opens no socket; a polled model after stop is dropped', async () => {
    const connect = deferred<string | null>();
    vi.mocked(session.client.connect).mockImplementation(() => connect.promise);
    session.start();
    await vi.advanceTimersByTimeAsync(0);
    session.stop();
    connect.resolve(null);
    await vi.advanceTimersByTimeAsync(10_000);
    expect(FakeSocket.all).toHaveLength(0);

    // Socket down long enough to poll: the poll's answer comes after stop.
    vi.mocked(session.client.connect).mockImplementation(async () => {
      session.client.connected = true;
      return null;
    });
    const polls: Array<ReturnType<typeof deferred<Record<string, unknown>>>> = [];
    vi.spyOn(session.client, 'modelRaw').mockImplementation(() => {
      const d = deferred<Record<string, unknown>>();
      polls.push(d);
      return d.promise;
    });
    const halted = () => ({ ...model(), state: { status: 'halted' } });
    const socketDownUntilPolled = async () => {
      const s = await online();
      s.drop(1006);
      const n = polls.length;
      await vi.advanceTimersByTimeAsync(POLL_AFTER_MS + POLL_EVERY_MS);
      expect(polls.length).toBeGreaterThan(n);
      return polls.at(-1);
    };
    const first = await socketDownUntilPolled();
    const before = { duet: session.store.getState(), snap: ctx.snapshot.getState() };
    session.stop();
    first?.resolve(halted());
    await vi.advanceTimersByTimeAsync(POLL_EVERY_MS * 3);
    expect(session.store.getState()).toBe(before.duet);
    expect(ctx.snapshot.getState()).toBe(before.snap);

    // Stop and a new start: the old run's answer must not be taken for the new run's.
    const old = await socketDownUntilPolled();
    session.stop();
    const again = await online();
    again.drop(1006); // the new run polls too (its socket is down)
    old?.resolve(halted());
    await vi.advanceTimersByTimeAsync(0);
    expect(session.store.getState().model?.state.status).toBe('idle');
    expect(ctx.snapshot.getState().activity).toBe('idle');
  });

  it('an upload that finishes after stop writes nothing; stop said it was cancelled', async () => {
    await online();
    const put = deferred<never>();
    vi.spyOn(session.client, 'upload').mockImplementation((_path, _body, opts) => {
      opts?.onProgress?.({ loaded: 1, total: 4 });
      return put.promise;
    });
    const run = ctx.commands.run(session.uploadCommandFor('0:/gcodes'), {
      file: new Blob(['G28\n']),
      name: 'a.gcode',
      dir: '0:/gcodes',
    });
    run.catch(() => undefined);
    await vi.advanceTimersByTimeAsync(0);
    expect(session.store.getState().uploads.at(-1)?.loaded).toBe(1);
    session.stop();
    expect(session.store.getState().uploads.at(-1)?.status).toBe('cancelled');
    const after = session.store.getState();
    put.reject(new Error('late failure'));
    await vi.advanceTimersByTimeAsync(0);
    await expect(run).rejects.toThrow();
    expect(session.store.getState()).toBe(after);
  });
});

describe('Duet session: kick after a command', () => {
  it('while the model is polled, a command is followed by a poll at once, not an interval later', async () => {
    const modelRaw = vi.spyOn(session.client, 'modelRaw').mockImplementation(async () => model());
    vi.spyOn(session.client, 'code').mockResolvedValue('');
    const s = await online();
    s.drop(1006); // the socket is down; it is retried on its backoff and stays refused
    vi.stubGlobal(
      'WebSocket',
      class extends FakeSocket {
        constructor(url: string) {
          super(url);
          queueMicrotask(() => this.drop(1006));
        }
      },
    );
    await vi.advanceTimersByTimeAsync(POLL_AFTER_MS + POLL_EVERY_MS);
    expect(session.store.getState().transport).toBe('polling');
    // Right after a poll: the next one is an interval away.
    const n = modelRaw.mock.calls.length;
    await vi.advanceTimersByTimeAsync(1);
    expect(modelRaw.mock.calls.length).toBe(n);
    await ctx.commands.run(session.cmd.console, { code: 'M106 S0.5' });
    await vi.advanceTimersByTimeAsync(1);
    expect(modelRaw.mock.calls.length).toBeGreaterThan(n);
    expect(ctx.snapshot.getState().link).toBe('online');
  });
});

describe('Duet session: heartbeat', () => {
  it('PING after 2 s of silence; no answer in 4 s is a dead link: reported, then a new socket', async () => {
    const s = await online();
    expect(s.sent).toEqual(['OK\n']);
    await vi.advanceTimersByTimeAsync(1500);
    s.frame(heaterPatch(22)); // data keeps the link alive
    await vi.advanceTimersByTimeAsync(1500);
    expect(s.sent).toEqual(['OK\n', 'OK\n']);
    await vi.advanceTimersByTimeAsync(1000);
    expect(s.sent.at(-1)).toBe('PING\n');
    s.frame('PONG\n'); // answered: alive, and a PONG is not acknowledged
    expect(s.sent.at(-1)).toBe('PING\n');
    await vi.advanceTimersByTimeAsync(2500); // silent again: a second PING, never answered
    expect(s.sent.filter((m) => m === 'PING\n')).toHaveLength(2);
    expect(ctx.snapshot.getState().link).toBe('online');
    await vi.advanceTimersByTimeAsync(4000);
    expect(ctx.snapshot.getState().link).toBe('reconnecting');
    expect(ctx.snapshot.getState().problem?.message).toMatch(/No answer to PING/);
    expect(s.closed).toBe(true);
    await vi.advanceTimersByTimeAsync(1000); // the socket's backoff (about 1 s)
    const again = last();
    expect(again).not.toBe(s);
    again.open();
    again.frame(model()); // a new socket starts with the full model
    expect(ctx.snapshot.getState().link).toBe('online');
    expect(again.sent).toEqual(['OK\n']);
    expect(session.store.getState().model?.heat.heaters[0]?.current).toBe(21);
  });
});

describe('Duet commands: availability follows the Duet store', () => {
  it('the cancel button turns available when the store says paused, with no snapshot change', async () => {
    await online();
    expect(session.cmd.cancel.needs).toContain(session.store);
    const reasons: Array<string | null> = [];
    function CancelState() {
      const reason = useBlockedReason(ctx.commands, ctx.snapshot, session.cmd.cancel);
      reasons.push(reason);
      return <span>{reason ?? 'available'}</span>;
    }
    const view = render(<CancelState />);
    expect(view.container.textContent).toMatch(/Pause the print first/);
    const snap = ctx.snapshot.getState();
    const paused = (status: 'paused' | 'processing') => {
      const m = session.store.getState().model;
      if (!m) throw new Error('no model');
      session.store.setState({ model: { ...m, state: { ...m.state, status } } });
    };
    act(() => paused('paused'));
    expect(ctx.snapshot.getState()).toBe(snap);
    expect(view.container.textContent).toBe('available');
    act(() => paused('processing'));
    expect(view.container.textContent).toMatch(/Pause the print first/);
  });
});

describe('Duet model: patches keep the identity of what they do not change', () => {
  it('a panel on the board and volumes renders once while heater frames arrive', async () => {
    const s = await online();
    const first = session.store.getState().model;
    let boardRenders = 0;
    let heaterRenders = 0;
    function Board() {
      boardRenders++;
      const d = useStoreSelect(session.store, (st) => ({
        board: st.model?.boards[0] ?? null,
        volumes: st.model?.volumes ?? null,
        mode: st.model?.state.machineMode ?? null,
      }));
      return <span>{d.board?.name}</span>;
    }
    function Heaters() {
      heaterRenders++;
      const heaters = useStoreSelect(session.store, (st) => st.model?.heat.heaters ?? null);
      return <span>{heaters?.[0]?.current}</span>;
    }
    render(
      <>
        <Board />
        <Heaters />
      </>,
    );
    expect([boardRenders, heaterRenders]).toEqual([1, 1]);
    for (let i = 1; i <= 5; i++) act(() => s.frame(heaterPatch(21 + i)));
    const m = session.store.getState().model;
    expect(m?.heat.heaters[0]?.current).toBe(26);
    expect(heaterRenders).toBe(6);
    expect(boardRenders).toBe(1);
    // Unchanged parts are the very objects of the first frame, and so is an unchanged heater.
    expect(m?.boards).toBe(first?.boards);
    expect(m?.move).toBe(first?.move);
    expect(m?.heat.heaters[1]).toBe(first?.heat.heaters[1]);
    // A frame that changes nothing notifies nobody.
    const state = session.store.getState();
    act(() => s.frame(heaterPatch(26)));
    expect(session.store.getState()).toBe(state);
    expect(heaterRenders).toBe(6);
  });
});
