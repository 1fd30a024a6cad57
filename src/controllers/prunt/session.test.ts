import { setupServer } from 'msw/node';
import { afterAll, afterEach, beforeAll, beforeEach, describe, expect, it, vi } from 'vitest';
import type { Principal } from '../../fleet/commands';
import { createContext } from '../../fleet/fleet';
import { alwaysVisible } from '../../fleet/link';
import { simulatorHandlers } from '../../fleet/msw';
import { jsonResponse, type Simulator } from '../../fleet/sim';
import type { Role } from '../../fleet/types';
import { memoryDraftStorage, type DraftStorage } from '../../forms/storage';
import { FLEET_DIVISOR, PruntSession } from './session';
import { loadBoard3 } from './sim/board';
import { PruntSimulator, type PruntApiGeneration } from './sim/sim';

const server = setupServer();
beforeAll(async () => {
  server.listen({ onUnhandledRequest: 'error' });
  // The simulator's board data is a lazy chunk: load it with real timers, once.
  await loadBoard3();
});
afterAll(() => server.close());

let seq = 0;
const cleanups: Array<() => void> = [];

beforeEach(() => {
  vi.useFakeTimers({ toFake: ['setTimeout', 'clearTimeout', 'setInterval', 'clearInterval', 'Date'] });
});
afterEach(() => {
  for (const c of cleanups.splice(0)) c();
  server.resetHandlers();
  vi.useRealTimers();
});

function setup(
  opts: {
    api?: PruntApiGeneration;
    role?: Role;
    drafts?: DraftStorage;
    wrap?: (s: PruntSimulator) => Simulator;
    id?: string;
  } = {},
) {
  const id = opts.id ?? `prunt-${++seq}`;
  const sim = new PruntSimulator({ id, name: 'Test printer', api: opts.api ?? 'module' });
  server.use(...simulatorHandlers(id, opts.wrap ? opts.wrap(sim) : sim));
  cleanups.push(() => sim.dispose());
  return { id, sim, ...connect(id, opts) };
}

function connect(id: string, opts: { role?: Role; drafts?: DraftStorage } = {}) {
  const principal = (): Principal => ({ name: 'tester', role: opts.role ?? 'supervisor' });
  const ctx = createContext(
    { id, name: 'Test printer', kind: 'prunt', simulated: true },
    { visibility: alwaysVisible, principal },
  );
  const session = new PruntSession(ctx, { drafts: opts.drafts ?? memoryDraftStorage() });
  cleanups.unshift(() => session.stop());
  return { ctx, session };
}

async function advance(ms: number): Promise<void> {
  for (let t = 0; t < ms; t += 50) await vi.advanceTimersByTimeAsync(50);
}

async function until(cond: () => boolean, maxMs = 10_000): Promise<void> {
  for (let t = 0; t < maxMs && !cond(); t += 50) await vi.advanceTimersByTimeAsync(50);
  expect(cond()).toBe(true);
}

describe('PruntSession against the simulator (module API)', () => {
  it('connects over the socket and fills the snapshot', async () => {
    const { ctx, session } = setup();
    session.start();
    await until(
      () => ctx.snapshot.getState().link === 'online' && session.store.getState().statusModel !== null,
    );
    await advance(1100);
    const snap = ctx.snapshot.getState();
    expect(snap.activity).toBe('idle');
    expect(snap.positions).toMatchObject({ X: 117.5, Y: 98.25 });
    expect(snap.temperatures.map((t) => t.name)).toEqual(['THERMISTOR_1', 'THERMISTOR_2']);
    expect(session.store.getState().api).toBe('module');
    expect(session.store.getState().update?.result).toEqual({ Available: false, URL: '' });
  });

  it('keeps the chart’s samples only while a page shows the machine’s details (a fleet page’s heap)', async () => {
    const id = `prunt-${++seq}`;
    const sim = new PruntSimulator({ id, name: 'Test printer', api: 'module' });
    server.use(...simulatorHandlers(id, sim));
    cleanups.push(() => sim.dispose());
    const detail = { shown: false };
    const ctx = createContext(
      { id, name: 'Test printer', kind: 'prunt', simulated: true },
      { visibility: alwaysVisible, detail: () => detail.shown },
    );
    const session = new PruntSession(ctx, { drafts: memoryDraftStorage() });
    cleanups.unshift(() => session.stop());
    session.start();
    await until(() => ctx.snapshot.getState().link === 'online');
    let ticks = 0;
    const unsub = session.store.subscribe((s, p) => void (s.statusAt !== p.statusAt && ticks++));
    await advance(30_000);
    unsub();
    expect(ticks).toBeGreaterThanOrEqual(20);
    expect(session.history.t).toHaveLength(0);
    detail.shown = true;
    await advance(5000);
    expect(session.history.t.length).toBeGreaterThanOrEqual(3);
    detail.shown = false;
    await advance(2000);
    expect(session.history.t).toHaveLength(0);
  });

  it('throttles with the divisor: 1 per second for the fleet, the chosen rate on the machine page', async () => {
    const { sim, session } = setup();
    session.start();
    await until(() => sim.socketDivisors()[0] === FLEET_DIVISOR);
    let ticks = 0;
    const unsub = session.store.subscribe((s, p) => void (s.statusAt !== p.statusAt && ticks++));
    await advance(2000);
    expect(ticks).toBeGreaterThanOrEqual(1);
    expect(ticks).toBeLessThanOrEqual(3);
    session.setLiveRate(10);
    const stop = session.watchLive();
    await advance(100);
    expect(sim.socketDivisors()).toEqual([2]);
    ticks = 0;
    await advance(2000);
    expect(ticks).toBeGreaterThanOrEqual(18);
    expect(ticks).toBeLessThanOrEqual(21);
    stop();
    await advance(100);
    expect(sim.socketDivisors()).toEqual([FLEET_DIVISOR]);
    unsub();
  });

  it('round trip: edit → save → server error under that field → fix → save → reload the server', async () => {
    const { sim, ctx, session } = setup();
    session.start();
    await until(() => ctx.snapshot.getState().link === 'online');
    await session.openConfig();
    const { model } = session.config.getState();
    if (!model) throw new Error('no model');
    const field = 'Steppers$Steppers$STEPPER_1$Run current';
    expect(model.value(field)).toBe(1.2);
    model.set(field, '3');
    expect(model.changes().map((c) => [c.from, c.to])).toEqual([[1.2, '3']]);
    await ctx.commands.run(session.cmd.saveConfig, undefined);
    // Semantic error: saved, and shown under the field it points at.
    expect(sim.values['Steppers$STEPPER_1$Run current']).toBe(3);
    expect(model.store.getState().serverErrors[field]?.[0]).toMatch(/overheat/);
    expect(model.store.getState().errorCounts['Steppers$Steppers$STEPPER_1']).toBe(1);
    expect(session.config.getState().lastSave?.saved).toBe(true);
    model.set(field, '2');
    await ctx.commands.run(session.cmd.saveConfig, undefined);
    expect(model.store.getState().serverErrors[field]).toBeUndefined();
    expect(model.changes()).toEqual([]);
    expect(session.config.getState().offerReload).toBe(true);
    // Reload: the server restarts with a new start time; the session refetches schema and values.
    const before = session.store.getState().startTime;
    await ctx.commands.run(session.cmd.reloadServer, undefined);
    await until(
      () => session.store.getState().startTime !== before && session.store.getState().startTime !== null,
    );
    await until(
      () => session.config.getState().phase === 'ready' && session.config.getState().notice !== null,
    );
    expect(session.config.getState().notice).toMatch(/restarted/);
    await until(() => ctx.snapshot.getState().link === 'online');
  });

  it('a schema error means nothing was saved: said so, errors under the fields, edits kept', async () => {
    const { ctx, session } = setup({
      wrap: (sim) => ({
        kind: 'prunt',
        socket: (p, s) => sim.socket(p, s),
        dispose: () => undefined,
        fetch: async (req, path) => {
          if (req.method === 'POST' && path === '/config/values') {
            const values = (await (
              await sim.fetch(new Request('http://x/config/values'), '/config/values')
            ).json()) as { Values: unknown };
            return jsonResponse({
              Values: values.Values,
              Errors: [
                {
                  Path: ['Config', 'Steppers', 'Config', 'Steppers', 'STEPPER_1', 'Run current'],
                  Message:
                    'Data does not match schema, no values will be saved: Element must not be greater than 3.00000000000000E+00',
                },
              ],
            });
          }
          return sim.fetch(req, path);
        },
      }),
    });
    session.start();
    await until(() => ctx.snapshot.getState().link === 'online');
    await session.openConfig();
    const model = session.config.getState().model;
    if (!model) throw new Error('no model');
    model.set('Steppers$Steppers$STEPPER_1$Run current', '2.5');
    await expect(ctx.commands.run(session.cmd.saveConfig, undefined)).rejects.toThrow(/Nothing was saved/);
    expect(session.config.getState().lastSave?.saved).toBe(false);
    expect(model.store.getState().serverErrors['Steppers$Steppers$STEPPER_1$Run current']).toHaveLength(1);
    expect(model.changes()).toHaveLength(1);
    expect(session.config.getState().offerReload).toBe(false);
  });

  it('unsaved edits survive a page reload (new session, same storage) and conflicts are named', async () => {
    const drafts = memoryDraftStorage();
    const { id, sim, ctx, session } = setup({ drafts });
    session.start();
    await until(() => ctx.snapshot.getState().link === 'online');
    await session.openConfig();
    session.config.getState().model?.set('Fans$Fans$FAN_1$PWM frequency', '20000');
    session.config.getState().model?.set('Fans$Fans$FAN_3$PWM frequency', '50');
    session.stop();
    // Meanwhile somebody changes FAN_3 on the controller.
    sim.values['Fans$FAN_3$PWM frequency'] = 60;
    const second = connect(id, { drafts });
    second.session.start();
    await second.session.openConfig();
    const m2 = second.session.config.getState().model;
    expect(m2?.value('Fans$Fans$FAN_1$PWM frequency')).toBe('20000');
    expect(m2?.store.getState().conflicts.map((c) => c.id)).toEqual(['Fans$Fans$FAN_3$PWM frequency']);
    expect(second.session.config.getState().notice).toMatch(/1 of your unsaved edits conflict/);
  });

  it('runs a file, refuses a second one with the controller text, pauses, resumes, cancels', async () => {
    const { ctx, session } = setup({ role: 'operator' });
    session.start();
    await until(
      () => ctx.snapshot.getState().link === 'online' && session.store.getState().startup === 'Done',
    );
    await ctx.commands.run(session.cmd.runFile, 'benchy.gcode');
    await until(() => ctx.snapshot.getState().activity === 'running');
    expect(ctx.snapshot.getState().job?.name).toBe('benchy.gcode');
    expect(session.commands['prunt.runFile']).toBeDefined();
    await expect(
      session.client.runFile('first_layer_test.gcode', { commandId: 'prunt.runFile' }),
    ).rejects.toThrow('Can not run file while another file is running.');
    await ctx.commands.run(session.cmd.pause, undefined);
    await until(() => ctx.snapshot.getState().activity === 'paused');
    await ctx.commands.run(session.cmd.resume, undefined);
    await until(() => ctx.snapshot.getState().activity === 'running');
    await ctx.commands.run(session.cmd.cancel, undefined);
    await until(() => ctx.snapshot.getState().activity === 'idle');
  });

  it('the G-code console follows Gcode_Command progress; laser commands fail with the controller text', async () => {
    const { ctx, session } = setup();
    session.start();
    await until(() => ctx.snapshot.getState().link === 'online');
    await ctx.commands.run(session.cmd.runCommand, 'M114');
    await until(() => session.store.getState().gcode[0]?.state === 'Completed');
    expect(session.store.getState().gcode[0]?.output[0]).toMatch(/^X:117\.500 Y:98\.250/);
    await ctx.commands.run(session.cmd.runCommand, 'M3 S100');
    await until(() => session.store.getState().gcode[1]?.state === 'Failed');
    expect(session.store.getState().gcode[1]?.output[0]).toMatch(/does not support lasers/);
  });

  it('an operator may not save the config or use the console', async () => {
    const { ctx, session } = setup({ role: 'operator' });
    session.start();
    await until(() => ctx.snapshot.getState().link === 'online');
    expect(ctx.commands.blockedReason(session.cmd.runCommand)).toMatch(/supervisor/);
    expect(ctx.commands.blockedReason(session.cmd.saveConfig)).toMatch(/supervisor/);
    expect(ctx.commands.blockedReason(session.cmd.pause)).toBe('Nothing is running');
  });

  it('firmware update required: alarm, and the supervisor action clears it', async () => {
    const { sim, ctx, session } = setup();
    session.start();
    await until(() => ctx.snapshot.getState().link === 'online');
    sim
      .controls()
      .find((c) => c.id === 'require-update')
      ?.run();
    await until(() => ctx.snapshot.getState().activity === 'alarm');
    expect(ctx.snapshot.getState().alarms[0]?.id).toBe('firmware-update-required');
    await ctx.commands.run(session.cmd.allowFirmwareUpdate, undefined);
    await until(() => ctx.snapshot.getState().activity === 'idle');
    expect(ctx.snapshot.getState().alarms).toEqual([]);
  });
});

describe('PruntSession: protocol errors', () => {
  it('a malformed status message is a visible protocol error with its path; a good one clears it', async () => {
    let broken = true;
    const { ctx, session } = setup({
      wrap: (sim) => ({
        kind: 'prunt',
        fetch: (req, path) => sim.fetch(req, path),
        dispose: () => undefined,
        socket: (p, sock) =>
          sim.socket(p, {
            send: (d) => sock.send(broken ? d.replace('"Startup": "Done"', '"Startup": 5') : d),
            close: (c, r) => sock.close(c, r),
          }),
      }),
    });
    session.start();
    await until(() => ctx.snapshot.getState().link === 'protocol-error');
    expect(ctx.snapshot.getState().problem?.path).toBe('Startup');
    broken = false;
    await until(() => ctx.snapshot.getState().link === 'online');
  });
});

describe('PruntSession against the flat API (2025)', () => {
  it('detects the flat API; the config values are fetched once, never polled', async () => {
    const { sim, ctx, session } = setup({ api: 'flat' });
    session.start();
    await until(() => ctx.snapshot.getState().link === 'online' && session.store.getState().api === 'flat');
    await session.openConfig();
    await advance(3000);
    expect(sim.configReads).toBe(1);
    expect(session.store.getState().update?.result).toEqual({ Available: false, URL: '' });
    const snap = ctx.snapshot.getState();
    expect(snap.temperatures.map((t) => t.name)).toEqual([
      'THERMISTOR_1',
      'THERMISTOR_2',
      'THERMISTOR_3',
      'THERMISTOR_4',
      'MAIN_MCU',
    ]);
    const model = session.config.getState().model;
    model?.set('Fans$FAN_2$PWM frequency', '200');
    await ctx.commands.run(session.cmd.saveConfig, undefined);
    expect(sim.configReads).toBe(1); // the POST reply carried the values: no second GET
    expect(model?.store.getState().serverErrors['Fans$FAN_2$PWM frequency']?.[0]).toMatch(
      /high-side switching mode/,
    );
  });
});
