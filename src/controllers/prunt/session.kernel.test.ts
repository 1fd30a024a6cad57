import { readFileSync } from 'node:fs';
import path from 'node:path';
import { setupServer } from 'msw/node';
import { afterAll, afterEach, beforeAll, beforeEach, describe, expect, it, vi } from 'vitest';
import type { Principal } from '../../fleet/commands';
import { createContext } from '../../fleet/fleet';
import { alwaysVisible } from '../../fleet/link';
import { simulatorHandlers } from '../../fleet/msw';
import type { Simulator } from '../../fleet/sim';
import { memoryDraftStorage } from '../../forms/storage';
import { FLEET_DIVISOR, PruntSession, SILENCE_MS } from './session';
import { loadBoard3 } from './sim/board';
import { PruntSimulator } from './sim/sim';

/**
 * The Prunt session on the kernel (issue 12): nothing written after stop, a status read right
 * after a command, the socket's heartbeat (3 s of silence is death → reconnect), and command
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

const FIXTURES = path.resolve(import.meta.dirname, '../../../tests/fixtures/prunt');

let seq = 0;

/**
 * A module-API simulator whose HTTP answers can be held back per path (`gates`), or answered by
 * the console server's own 502 (`broken`: it could not reach the controller).
 */
function setup() {
  const id = `pk-${++seq}`;
  const sim = new PruntSimulator({ id, name: 'Kernel printer', api: 'module' });
  const gates = new Map<string, Promise<void>>();
  const broken = new Set<string>();
  /** Paths answered with this text (200) instead of the simulator's answer. */
  const answers = new Map<string, string>();
  const requests: string[] = [];
  const wrapped: Simulator = {
    kind: 'prunt',
    dispose: () => undefined,
    fetch: async (req, path) => {
      requests.push(`${req.method} ${path}`);
      await gates.get(path);
      const text = answers.get(path);
      if (text !== undefined) return new Response(text, { headers: { 'Content-Type': 'application/json' } });
      if (broken.has(path))
        return new Response(JSON.stringify({ error: 'cannot reach the controller', gateway: true }), {
          status: 502,
          headers: { 'Content-Type': 'application/json', 'X-Shopdeck-Gateway': 'error' },
        });
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
  return { id, sim, ctx, session, gates, broken, answers, requests, tick, statusReads };
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
    // The editor's code is a chunk of its own: the schema is read once it is there.
    await vi.waitFor(() => expect(t.session.config.getState().model).not.toBeNull());
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
    // No status reads while the socket ticks (once a second) and nothing was commanded.
    for (let i = 0; i < 5; i++) {
      await vi.advanceTimersByTimeAsync(1000);
      last().message(await t.tick());
    }
    expect(FakeSocket.all).toHaveLength(1);
    expect(t.statusReads()).toBe(0);
    expect(t.ctx.snapshot.getState().activity).toBe('idle');
    await t.ctx.commands.run(t.session.cmd.runFile, 'benchy.gcode');
    await vi.advanceTimersByTimeAsync(0);
    // No tick came from the socket: the read after the command brought it.
    expect(t.statusReads()).toBe(1);
    expect(t.ctx.snapshot.getState().activity).toBe('running');
    expect(t.ctx.snapshot.getState().job?.name).toBe('benchy.gcode');
    // One read per command, then quiet again while the socket ticks.
    for (let i = 0; i < 5; i++) {
      last().message(await t.tick());
      await vi.advanceTimersByTimeAsync(1000);
    }
    expect(t.ctx.snapshot.getState().link).toBe('online');
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

describe('Prunt: the socket heartbeat (3 s of silence is a dead link: down within 5 s)', () => {
  it('silence → reconnecting with the reason → a new socket, the divisor again, online again', async () => {
    expect(SILENCE_MS).toBe(3000);
    const t = setup();
    const first = await online(t);
    expect(first.sent).toEqual([String(FLEET_DIVISOR)]);
    await vi.advanceTimersByTimeAsync(2500);
    first.message(await t.tick()); // ticks keep it alive
    await vi.advanceTimersByTimeAsync(2500);
    expect(t.ctx.snapshot.getState().link).toBe('online');
    expect(FakeSocket.all).toHaveLength(1);
    await vi.advanceTimersByTimeAsync(1000); // 3.5 s since the last tick (checked every 0.5 s)
    expect(t.ctx.snapshot.getState().link).toBe('reconnecting');
    expect(t.ctx.snapshot.getState().problem?.message).toMatch(
      /No status from the controller \(No data for 3 s\)/,
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

  it('a socket that opens but never speaks is dead after 3 s too', async () => {
    const t = setup();
    t.session.start();
    last().open();
    await vi.advanceTimersByTimeAsync(2500);
    expect(t.ctx.snapshot.getState().link).toBe('connecting');
    expect(FakeSocket.all[0]?.closed).toBe(false);
    await vi.advanceTimersByTimeAsync(1000);
    expect(t.ctx.snapshot.getState().link).toBe('reconnecting');
    expect(t.ctx.snapshot.getState().problem?.message).toMatch(/No data after connecting/);
    expect(FakeSocket.all[0]?.closed).toBe(true);
    await vi.advanceTimersByTimeAsync(1000);
    expect(FakeSocket.all).toHaveLength(2);
  });
});

describe('Prunt: the status schema read after a failure', () => {
  it('is a link fault, retried quickly by one retry loop however often the socket reopens', async () => {
    const t = setup();
    t.broken.add('/status/schema');
    const schemaReads = () => t.requests.filter((r) => r === 'GET /status/schema').length;
    t.session.start();
    await settle();
    expect(schemaReads()).toBe(1);
    expect(t.ctx.snapshot.getState().link).toBe('reconnecting');
    expect(t.ctx.snapshot.getState().problem?.message).toMatch(/cannot reach the controller/);
    // Each new socket that opens asks again (the HTTP side may be back): four of them here.
    for (let i = 0; i < 4; i++) {
      last().open();
      last().message('{"Server_Start_Time": " 1000.5"}');
      await settle();
      last().onclose?.({ code: 1006, reason: '' });
      await vi.advanceTimersByTimeAsync(1000);
    }
    const before = schemaReads();
    // 12 s of outage: one loop, ≤ 2.5 s apart (1, 2, 2.5, 2.5 … s), not one loop per socket opened.
    for (let i = 0; i < 24; i++) {
      await vi.advanceTimersByTimeAsync(500);
      await new Promise<void>((r) => setImmediate(r));
    }
    const during = schemaReads() - before;
    expect(during).toBeGreaterThanOrEqual(3);
    expect(during).toBeLessThanOrEqual(7);
    // The controller answers again: the machine has its schema within 5 s, without a restart.
    t.broken.clear();
    for (let i = 0; i < 10 && !t.session.store.getState().statusModel; i++) {
      await vi.advanceTimersByTimeAsync(500);
      await new Promise<void>((r) => setImmediate(r));
    }
    expect(t.session.store.getState().statusModel).not.toBeNull();
    expect(t.session.store.getState().api).toBe('module');
  });
});

describe('Prunt: an unsaved config edit survives the schema answers of a reload', () => {
  const FIELD = 'Steppers$Steppers$STEPPER_1$Run current';

  async function editing(t: ReturnType<typeof setup>) {
    await online(t);
    await t.session.openConfig();
    const model = t.session.config.getState().model;
    model?.set(FIELD, '2.5');
    const kept = () =>
      t.session.config
        .getState()
        .model?.changes()
        .some((c) => c.id === FIELD && c.to === '2.5') ?? false;
    expect(kept()).toBe(true);
    return { model, kept };
  }

  it('a schema of the other API generation is refused in words; the form and the edit stay', async () => {
    const t = setup();
    const { model, kept } = await editing(t);
    t.answers.set('/config/schema', readFileSync(path.join(FIXTURES, 'config-schema.json'), 'utf8'));
    await t.session.loadConfig(null);
    const c = t.session.config.getState();
    expect(c.phase).toBe('error');
    expect(c.error).toMatch(
      /config schema is of the flat API \(2025\), but this controller speaks the module API/,
    );
    expect(c.model).toBe(model);
    expect(c.form?.api).toBe('module');
    expect(kept()).toBe(true);
    // The true schema again: the editor is ready, with the edit.
    t.answers.clear();
    await t.session.loadConfig(null);
    expect(t.session.config.getState().phase).toBe('ready');
    expect(kept()).toBe(true);
  });

  it('a changed schema that no longer holds the edit does not replace the form until the edit is discarded', async () => {
    const t = setup();
    const { model, kept } = await editing(t);
    const res = await t.sim.fetch(new Request('http://x/config/schema'), '/config/schema');
    const schema = (await res.json()) as { Config: Record<string, unknown> };
    delete schema.Config['Steppers'];
    t.answers.set('/config/schema', JSON.stringify(schema));
    await t.session.loadConfig(null);
    const c = t.session.config.getState();
    expect(c.phase).toBe('error');
    expect(c.error).toMatch(
      /schema changed and no longer holds your unsaved edit \(Steppers › STEPPER_1 › Run current\): discard it/,
    );
    expect(c.model).toBe(model);
    expect(kept()).toBe(true);
    // The user discards it: the new schema is taken.
    model?.discardAll();
    await t.session.loadConfig(null);
    expect(t.session.config.getState().phase).toBe('ready');
    expect(t.session.config.getState().model).not.toBe(model);
    expect(t.session.config.getState().form?.form.nodes.has(FIELD)).toBe(false);
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
