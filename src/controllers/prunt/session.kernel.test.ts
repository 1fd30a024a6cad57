import { setupServer } from 'msw/node';
import { afterAll, afterEach, beforeAll, beforeEach, describe, expect, it, vi } from 'vitest';
import type { Principal } from '../../fleet/commands';
import { createContext } from '../../fleet/fleet';
import { alwaysVisible } from '../../fleet/link';
import { simulatorHandlers } from '../../fleet/msw';
import type { Simulator } from '../../fleet/sim';
import { memoryDraftStorage } from '../../forms/storage';
import { FLEET_DIVISOR, PruntSession } from './session';
import { loadBoard3 } from './sim/board';
import { PruntSimulator } from './sim/sim';

/**
 * The Prunt session on the kernel (issue 12): nothing written after stop, a status read right
 * after a command, the socket's heartbeat (10 s of silence is death → reconnect), and command
 * availability from the stores it names. HTTP goes to the simulator through msw; the socket is
 * a double the test feeds by hand (fake timers drive time).
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
  message(data: string): void {
    this.onmessage?.({ data });
  }
  send(d: string): void {
    this.sent.push(d);
  }
  close(): void {
    this.closed = true;
    this.readyState = 3;
  }
}

const last = (): FakeSocket => {
  const s = FakeSocket.all[FakeSocket.all.length - 1];
  if (!s) throw new Error('no socket');
  return s;
};

const server = setupServer();
beforeAll(async () => {
  server.listen({ onUnhandledRequest: 'error' });
  await loadBoard3();
});
afterAll(() => server.close());

const cleanups: Array<() => void> = [];
beforeEach(() => {
  vi.useFakeTimers({ toFake: ['setTimeout', 'clearTimeout', 'setInterval', 'clearInterval', 'Date'] });
  FakeSocket.all = [];
  vi.stubGlobal('WebSocket', FakeSocket);
});
afterEach(() => {
  for (const c of cleanups.splice(0)) c();
  server.resetHandlers();
  vi.unstubAllGlobals();
  vi.useRealTimers();
});

function deferred(): { promise: Promise<void>; release: () => void } {
  let release!: () => void;
  const promise = new Promise<void>((r) => (release = r));
  return { promise, release };
}

/** Lets answers travel: fake time and real event-loop turns (msw answers through real I/O). */
async function settle(): Promise<void> {
  for (let i = 0; i < 20; i++) {
    await vi.advanceTimersByTimeAsync(5);
    await new Promise<void>((r) => setImmediate(r));
  }
}

let seq = 0;

/** A module-API simulator whose HTTP answers can be held back per path (`gates`). */
function setup() {
  const id = `pk-${++seq}`;
  const sim = new PruntSimulator({ id, name: 'Kernel printer', api: 'module' });
  const gates = new Map<string, Promise<void>>();
  const requests: string[] = [];
  const wrapped: Simulator = {
    kind: 'prunt',
    dispose: () => undefined,
    fetch: async (req, path) => {
      requests.push(`${req.method} ${path}`);
      await gates.get(path);
      return sim.fetch(req, path);
    },
  };
  server.use(...simulatorHandlers(id, wrapped));
  const principal = (): Principal => ({ name: 'tester', role: 'supervisor' });
  const ctx = createContext(
    { id, name: 'Kernel printer', kind: 'prunt', simulated: true },
    { visibility: alwaysVisible, principal },
  );
  const session = new PruntSession(ctx, { drafts: memoryDraftStorage() });
  cleanups.push(() => {
    session.stop();
    sim.dispose();
  });
  /** A tick as the server sends it, with the simulator's current values. */
  const tick = async (startup = 'Done'): Promise<string> => {
    const res = await sim.fetch(new Request('http://x/status/values'), '/status/values');
    const values: unknown = await res.json();
    return JSON.stringify({
      Status_Values: values,
      Smart_Plug: null,
      Server_Exception: null,
      Startup: startup,
    });
  };
  const statusReads = () => requests.filter((r) => r === 'GET /status/values').length;
  return { id, sim, ctx, session, gates, requests, tick, statusReads };
}

/** Start, open the socket, let the schema arrive and one tick make the machine online. */
async function online(t: ReturnType<typeof setup>): Promise<FakeSocket> {
  t.session.start();
  const sock = last();
  sock.open();
  await vi.advanceTimersByTimeAsync(0);
  expect(t.session.store.getState().statusModel).not.toBeNull();
  sock.message('{"Server_Start_Time": " 1000.5"}');
  sock.message(await t.tick());
  await vi.advanceTimersByTimeAsync(0);
  expect(t.ctx.snapshot.getState().link).toBe('online');
  return sock;
}

describe('Prunt: nothing is written after stop', () => {
  it('drops socket frames that arrive (or are still batched) after stop', async () => {
    const t = setup();
    const sock = await online(t);
    const store = t.session.store.getState();
    const snap = t.ctx.snapshot.getState();
    const log = t.ctx.log.store.getState().entries.length;
    const handler = sock.onmessage;
    // Batched for the next frame, then the session stops before the frame comes.
    sock.message(await t.tick('Update_Required'));
    t.session.stop();
    // A frame that reaches the old handler after stop.
    handler?.({ data: await t.tick('Update_Required') });
    handler?.({ data: '{"Log": "Setup done."}' });
    await settle();
    expect(t.session.store.getState()).toBe(store);
    expect(t.ctx.snapshot.getState()).toBe(snap);
    expect(t.ctx.log.store.getState().entries).toHaveLength(log);
    expect(sock.closed).toBe(true);
  });

  it('drops the status schema answer of a stopped run, and a new run reads it again', async () => {
    const t = setup();
    const gate = deferred();
    t.gates.set('/status/schema', gate.promise);
    t.session.start();
    await vi.advanceTimersByTimeAsync(0);
    expect(t.requests).toContain('GET /status/schema');
    t.session.stop();
    gate.release();
    await settle();
    expect(t.session.store.getState().statusModel).toBeNull();
    expect(t.session.store.getState().api).toBeNull();
    expect(t.session.store.getState().update).toBeNull();
    expect(t.ctx.snapshot.getState().link).toBe('connecting');
    expect(t.ctx.log.store.getState().entries.filter((e) => e.source === 'link')).toEqual([]);
    t.gates.clear();
    t.session.start();
    await vi.advanceTimersByTimeAsync(0);
    expect(t.session.store.getState().api).toBe('module');
  });

  it('drops the answer of the status read that follows a command when the session stopped meanwhile', async () => {
    const t = setup();
    await online(t);
    const gate = deferred();
    t.gates.set('/status/values', gate.promise);
    // The controller starts a file: the read would show it running.
    await t.sim.fetch(
      new Request('http://x/run-file', { method: 'POST', body: 'benchy.gcode' }),
      '/run-file',
    );
    await vi.advanceTimersByTimeAsync(1000);
    t.session.kick();
    await vi.advanceTimersByTimeAsync(0);
    expect(t.statusReads()).toBe(1);
    const store = t.session.store.getState();
    const snap = t.ctx.snapshot.getState();
    t.session.stop();
    gate.release();
    await settle();
    expect(t.session.store.getState()).toBe(store);
    expect(t.ctx.snapshot.getState()).toBe(snap);
    expect(snap.activity).toBe('idle');
  });

  it('a config load cut by stop writes nothing, and a new run loads the editor meanwhile', async () => {
    const t = setup();
    await online(t);
    const gate = deferred();
    t.gates.set('/config/values', gate.promise);
    const opening = t.session.openConfig();
    await vi.advanceTimersByTimeAsync(0);
    expect(t.session.config.getState().phase).toBe('loading');
    const model = t.session.config.getState().model;
    expect(model?.store.getState().loaded).toBe(false);
    t.session.stop();
    await settle();
    expect(model?.store.getState().loaded).toBe(false);
    expect(t.session.config.getState().phase).toBe('loading');
    // A new run while the old read is still on its way: the editor loads, not waits for it.
    t.gates.clear();
    t.session.start();
    await t.session.openConfig();
    expect(t.session.config.getState().phase).toBe('ready');
    expect(model?.store.getState().loaded).toBe(true);
    const ready = t.session.config.getState();
    gate.release();
    await opening;
    await settle();
    expect(t.session.config.getState()).toBe(ready);
  });
});

describe('Prunt: a command is followed by a status read at once (kick)', () => {
  it('shows the file running right after "Run file", without waiting for the next tick', async () => {
    const t = setup();
    await online(t);
    // No status reads while the socket ticks and nothing was commanded.
    await vi.advanceTimersByTimeAsync(5000);
    last().message(await t.tick());
    expect(t.statusReads()).toBe(0);
    expect(t.ctx.snapshot.getState().activity).toBe('idle');
    await t.ctx.commands.run(t.session.cmd.runFile, 'benchy.gcode');
    await vi.advanceTimersByTimeAsync(0);
    // No tick came from the socket: the read after the command brought it.
    expect(t.statusReads()).toBe(1);
    expect(t.ctx.snapshot.getState().activity).toBe('running');
    expect(t.ctx.snapshot.getState().job?.name).toBe('benchy.gcode');
    // One read per command, then quiet again.
    last().message(await t.tick());
    await vi.advanceTimersByTimeAsync(5000);
    expect(t.statusReads()).toBe(1);
  });

  it('a command sent while the status read is in flight gets a read of its own right after it', async () => {
    const t = setup();
    await online(t);
    const gate = deferred();
    t.gates.set('/status/values', gate.promise);
    await t.ctx.commands.run(t.session.cmd.runFile, 'benchy.gcode');
    await vi.advanceTimersByTimeAsync(0);
    expect(t.statusReads()).toBe(1);
    t.session.kick(); // e.g. a G-code sent while the first read is on its way
    t.gates.clear();
    gate.release();
    await vi.advanceTimersByTimeAsync(0);
    await vi.advanceTimersByTimeAsync(0);
    expect(t.statusReads()).toBe(2);
    expect(t.ctx.snapshot.getState().activity).toBe('running');
  });
});

describe('Prunt: the socket heartbeat (10 s of silence is a dead link)', () => {
  it('silence → reconnecting with the reason → a new socket, the divisor again, online again', async () => {
    const t = setup();
    const first = await online(t);
    expect(first.sent).toEqual([String(FLEET_DIVISOR)]);
    await vi.advanceTimersByTimeAsync(9000);
    first.message(await t.tick()); // ticks keep it alive
    await vi.advanceTimersByTimeAsync(9000);
    expect(t.ctx.snapshot.getState().link).toBe('online');
    expect(FakeSocket.all).toHaveLength(1);
    await vi.advanceTimersByTimeAsync(1500); // 10 s since the last tick
    expect(t.ctx.snapshot.getState().link).toBe('reconnecting');
    expect(t.ctx.snapshot.getState().problem?.message).toMatch(
      /No status from the controller \(No data for 10 s\)/,
    );
    expect(first.closed).toBe(true);
    await vi.advanceTimersByTimeAsync(1000); // backoff ≤ 1 s
    expect(FakeSocket.all).toHaveLength(2);
    const second = last();
    second.open();
    expect(second.sent).toEqual([String(FLEET_DIVISOR)]);
    second.message(await t.tick());
    await vi.advanceTimersByTimeAsync(0);
    expect(t.ctx.snapshot.getState().link).toBe('online');
  });

  it('a socket that opens but never speaks is dead after 10 s too', async () => {
    const t = setup();
    t.session.start();
    last().open();
    await vi.advanceTimersByTimeAsync(10_500);
    expect(t.ctx.snapshot.getState().problem?.message).toMatch(/No data after connecting/);
    await vi.advanceTimersByTimeAsync(1000);
    expect(FakeSocket.all).toHaveLength(2);
  });
});

describe('Prunt: availability reads the stores the commands name', () => {
  it('"Allow firmware update" follows the Prunt store alone; "Save" follows the editor\'s edits', async () => {
    const t = setup();
    await online(t);
    const allow = t.session.cmd.allowFirmwareUpdate;
    const save = t.session.cmd.saveConfig;
    expect(allow.needs).toContain(t.session.store);
    expect(save.needs).toContain(t.session.config);
    expect(t.ctx.commands.blockedReason(allow)).toBe('No firmware update is required');
    const snap = t.ctx.snapshot.getState();
    t.session.store.setState({ startup: 'Update_Required' });
    expect(t.ctx.snapshot.getState()).toBe(snap);
    expect(t.ctx.commands.blockedReason(allow)).toBeNull();

    await t.session.openConfig();
    expect(t.ctx.commands.blockedReason(save)).toBe('No changes to save');
    const seen = vi.fn();
    const unsub = t.session.config.subscribe(seen);
    const model = t.session.config.getState().model;
    model?.set('Steppers$Steppers$STEPPER_1$Run current', '2');
    expect(seen).toHaveBeenCalled(); // a button on "Save" hears of the edit
    expect(t.ctx.commands.blockedReason(save)).toBeNull();
    model?.set('Steppers$Steppers$STEPPER_1$Run current', '99');
    expect(t.ctx.commands.blockedReason(save)).toBe('Fix the invalid values first');
    model?.discardAll();
    expect(t.ctx.commands.blockedReason(save)).toBe('No changes to save');
    unsub();
  });
});
