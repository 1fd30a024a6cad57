import { setupServer } from 'msw/node';
import { afterAll, afterEach, beforeAll, beforeEach, describe, expect, it, vi } from 'vitest';
import { createContext } from '../../fleet/fleet';
import { alwaysVisible, SocketLink } from '../../fleet/link';
import { simulatorHandlers } from '../../fleet/msw';
import { FaultySimulator } from '../../fleet/sim';
import type { SessionContext } from '../../fleet/contract';
import { fileInfoKey } from './reads';
import { DuetSession, messageBoxReply, TILE_ACK_MS } from './session';
import { DuetSimulator } from './sim/simulator';

let sim: DuetSimulator;
let faulty: FaultySimulator;
const server = setupServer();
let ctx: SessionContext;
let session: DuetSession;

beforeAll(() => server.listen({ onUnhandledRequest: 'error' }));
afterAll(() => server.close());

beforeEach(() => {
  vi.useFakeTimers({ toFake: ['setTimeout', 'clearTimeout', 'setInterval', 'clearInterval', 'Date'] });
  sim = new DuetSimulator({ id: 'dm', name: 'duet-sim', now: () => Date.now(), tickMs: 250 });
  faulty = new FaultySimulator(sim);
  server.resetHandlers(...simulatorHandlers('dm', faulty));
  ctx = createContext(
    { id: 'dm', name: 'Duet', kind: 'duet', simulated: true },
    { visibility: alwaysVisible, principal: () => ({ name: 'tester', role: 'supervisor' }) },
  );
  session = new DuetSession(ctx);
});

afterEach(() => {
  session.stop();
  sim.dispose();
  vi.useRealTimers();
});

/** Advance fake time in small steps so sockets, fetches and timers interleave. */
async function advance(ms: number, step = 50): Promise<void> {
  for (let t = 0; t < ms; t += step) await vi.advanceTimersByTimeAsync(step);
}

async function until(pred: () => boolean, maxMs = 10_000): Promise<void> {
  for (let t = 0; t < maxMs; t += 50) {
    if (pred()) return;
    await vi.advanceTimersByTimeAsync(50);
  }
  throw new Error('condition not met in time');
}

const status = () => session.store.getState().model?.state.status;
const snap = () => ctx.snapshot.getState();

describe('DuetSession through msw', () => {
  it('connects, takes the full model, then follows patches (and acknowledges each)', async () => {
    session.start();
    await until(() => snap().link === 'online');
    expect(status()).toBe('idle');
    expect(snap().identity).toMatch(/Simulated Duet 3 Mini 5\+ · RRF 3\.5\.1 · DSF 3\.5\.1/);
    expect(snap().temperatures.map((t) => t.name)).toEqual(['Bed', 'Hotend (T0)', 'Chamber']);
    sim.runCode('M140 S60');
    await until(() => (session.store.getState().model?.heat.heaters[0]?.current ?? 0) > 25);
    expect(snap().temperatures[0]?.target).toBe(60);
  });

  it('on a tile only, asks for a patch a second (TILE_ACK_MS); on its page, after each one at once', async () => {
    let detail = false;
    ctx = createContext(
      { id: 'dm', name: 'Duet', kind: 'duet', simulated: true },
      {
        visibility: alwaysVisible,
        principal: () => ({ name: 'tester', role: 'supervisor' }),
        detail: () => detail,
      },
    );
    session.stop();
    session = new DuetSession(ctx);
    const send = vi.spyOn(SocketLink.prototype, 'send');
    session.start();
    await until(() => snap().link === 'online');
    sim.runCode('M140 S60');
    send.mockClear();
    await advance(5000);
    for (const c of send.mock.calls) expect(c[0]).toBe('OK\n');
    const tileOks = send.mock.calls.length;
    // The simulator changes the model every 250 ms: twenty patches' worth, asked for five times.
    expect(tileOks).toBeGreaterThanOrEqual(4);
    expect(tileOks).toBeLessThanOrEqual(6);
    // Nothing lost: the next patch carries every change made meanwhile.
    const heater = () => session.store.getState().model?.heat.heaters[0]?.current ?? 0;
    const simHeater = (): number => {
      const heat = sim.model['heat'];
      const heaters = heat && typeof heat === 'object' && !Array.isArray(heat) ? heat['heaters'] : null;
      const h = Array.isArray(heaters) ? heaters[0] : null;
      const v = h && typeof h === 'object' && !Array.isArray(h) ? h['current'] : null;
      return typeof v === 'number' ? v : NaN;
    };
    await advance(TILE_ACK_MS + 300);
    expect(heater()).toBeGreaterThan(25);
    expect(Math.abs(heater() - simHeater())).toBeLessThan(5);
    detail = true;
    await advance(TILE_ACK_MS);
    send.mockClear();
    await advance(2000);
    expect(send.mock.calls.length).toBeGreaterThanOrEqual(6);
    send.mockRestore();
  });

  it('declares its commands by id, each with a role that matches the access policy', () => {
    const ids = Object.keys(session.commands);
    expect(ids).toContain('duet.pause');
    expect(ids.every((id) => id.startsWith('duet.') && session.commands[id]?.id === id)).toBe(true);
    expect(session.commands['duet.estop']?.role).toBe('operator');
    expect(session.commands['duet.code']?.role).toBe('supervisor');
  });

  it('start, pause and cancel a print; messages land in the console log', async () => {
    session.start();
    await until(() => snap().link === 'online');
    const cmds = session.cmd;
    expect(ctx.commands.blockedReason(cmds.cancel)).toMatch(/Pause the print first/);
    await ctx.commands.run(cmds.start, { path: '0:/gcodes/bracket.gcode' });
    await until(() => status() === 'processing');
    await until(() => (snap().job?.progress ?? 0) > 0.05, 200_000);
    expect(snap().activity).toBe('running');
    expect(snap().job?.name).toBe('bracket.gcode');
    expect(ctx.commands.blockedReason(cmds.cancel)).not.toBeNull();
    await ctx.commands.run(cmds.pause, undefined);
    await until(() => status() === 'paused');
    expect(snap().activity).toBe('paused');
    expect(ctx.commands.blockedReason(cmds.cancel)).toBeNull();
    await ctx.commands.run(cmds.cancel, undefined);
    await until(() => status() === 'idle');
    const texts = ctx.log.store.getState().entries.map((e) => `${e.source}:${e.text}`);
    expect(texts).toContain('controller:Started printing file 0:/gcodes/bracket.gcode');
    expect(
      texts.some((t) => t.startsWith('controller:Cancelled printing file 0:/gcodes/bracket.gcode')),
    ).toBe(true);
    expect(sim.codes).toEqual(['M32 "0:/gcodes/bracket.gcode"', 'M25', 'M0']);
  });

  it('an error reply fails the command and is logged', async () => {
    session.start();
    await until(() => snap().link === 'online');
    await expect(ctx.commands.run(session.cmd.start, { path: '0:/gcodes/missing.gcode' })).rejects.toThrow(
      /Could not find file/,
    );
    expect(ctx.log.store.getState().entries.some((e) => e.level === 'error' && e.source === 'console')).toBe(
      true,
    );
  });

  it('emergency stop sends M112 then M999 in one request, without confirmation', async () => {
    session.start();
    await until(() => snap().link === 'online');
    expect(session.cmd.estop.confirm).toBe(false);
    await ctx.commands.run(session.cmd.estop, undefined);
    expect(sim.codes).toEqual(['M112', 'M999']);
    await until(() => status() === 'idle');
  });

  it('sends PING after 2 s of silence and reconnects when no PONG comes', async () => {
    session.start();
    await until(() => snap().link === 'online');
    sim.frozen = true;
    await advance(2600);
    expect(sim.pings).toBeGreaterThanOrEqual(1);
    expect(snap().link).toBe('online');
    await until(() => snap().link === 'reconnecting', 8000);
    expect(snap().problem?.message).toMatch(/PING/);
    sim.frozen = false;
    await until(() => snap().link === 'online', 30_000);
  });

  it('socket close 1011 means the DSF service is down; the console history survives the reconnect', async () => {
    session.start();
    await until(() => snap().link === 'online');
    await ctx.commands.run(session.cmd.console, { code: 'M115' });
    const before = ctx.log.store
      .getState()
      .entries.filter((e) => e.source === 'console')
      .map((e) => e.text);
    expect(before.some((t) => t.startsWith('FIRMWARE_NAME'))).toBe(true);
    sim.closeSockets(1011, 'DCS is unavailable');
    await until(() => snap().link === 'reconnecting');
    expect(snap().problem?.message).toMatch(/DSF\) or the link to it is down/);
    await until(() => snap().link === 'online', 30_000);
    const after = ctx.log.store
      .getState()
      .entries.filter((e) => e.source === 'console')
      .map((e) => e.text);
    expect(after.slice(0, before.length)).toEqual(before);
    expect(session.store.getState().codeHistory).toEqual(['M115']);
  });

  it('an expired session reconnects once silently; a command is not replayed', async () => {
    session.start();
    await until(() => snap().link === 'online');
    sim.expireSessions();
    await expect(ctx.commands.run(session.cmd.console, { code: 'M115' })).rejects.toThrow(/NOT carried out/);
    expect(sim.codes).toEqual([]);
    await until(() => snap().link === 'online' && session.client.sessionKey !== null);
    await ctx.commands.run(session.cmd.console, { code: 'M115' });
    expect(sim.codes).toEqual(['M115']);
    expect(snap().link).toBe('online');
  });

  it('needs login when the password is wrong, and logs in with the right one', async () => {
    sim.password = 'secret';
    session.start();
    await until(() => snap().link === 'needs-login');
    expect(session.store.getState().needsPassword).toBe(true);
    await expect(session.login({ password: 'nope' })).rejects.toThrow(/refused/);
    await session.login({ password: 'secret' });
    await until(() => snap().link === 'online');
    // the session dies and the password changed: one silent retry, then needs-login again
    sim.password = 'other';
    sim.expireSessions();
    sim.closeSockets(4000, 'simulated socket close');
    await until(() => snap().link === 'needs-login', 60_000);
  });

  it('while the socket cannot be opened, polls GET /machine/model and retries the socket', async () => {
    const socket = sim.socket.bind(sim);
    sim.socket = () => null; // sockets refused (msw closes them), e.g. a proxy without WebSocket
    session.start();
    await until(() => session.store.getState().transport === 'polling', 20_000);
    expect(snap().link).toBe('online');
    expect(status()).toBe('idle');
    expect(session.store.getState().socketProblem).toMatch(/Socket closed/);
    // The data follows the machine (slower).
    sim.runCode('M32 "0:/gcodes/bracket.gcode"');
    await until(() => status() === 'processing');
    const polls = sim.requests.filter((r) => r === 'GET /machine/model').length;
    expect(polls).toBeGreaterThan(1);
    // The socket is retried; once it works, polling stops.
    sim.socket = socket;
    await until(() => session.store.getState().transport === 'socket', 40_000);
    const after = sim.requests.filter((r) => r === 'GET /machine/model').length;
    await advance(10_000, 100);
    expect(sim.requests.filter((r) => r === 'GET /machine/model').length).toBe(after);
    expect(snap().link).toBe('online');
  });

  it('a socket that comes back quickly does not switch to polling', async () => {
    session.start();
    await until(() => snap().link === 'online');
    sim.closeSockets(1011, 'DCS is unavailable');
    await until(() => snap().link === 'online' && session.store.getState().transport === 'socket', 20_000);
    await advance(3000, 100);
    expect(sim.requests).not.toContain('GET /machine/model');
  });

  it('without a socket and without a model keeps the link down (no polling success)', async () => {
    sim.socket = () => null;
    session.start();
    await until(() => sim.requests.includes('GET /machine/connect'));
    sim.password = 'secret'; // every later request is refused
    sim.expireSessions();
    await advance(20_000, 100);
    expect(snap().link).not.toBe('online');
  });

  it('answers message boxes with M292 as the firmware expects', async () => {
    session.start();
    await until(() => snap().link === 'online');
    sim.raiseMessageBox(5);
    await until(() => session.store.getState().model?.state.messageBox?.mode === 5);
    expect(snap().alarms.some((a) => a.id.startsWith('messagebox-'))).toBe(true);
    const box = session.store.getState().model!.state.messageBox!;
    await ctx.commands.run(session.cmd.answer, { box, value: 7 });
    expect(sim.answers.at(-1)).toEqual({ seq: box.seq, cancelled: false, value: '7' });
    await until(() => session.store.getState().model?.state.messageBox === null);
    sim.raiseMessageBox(3);
    await until(() => session.store.getState().model?.state.messageBox?.mode === 3);
    const box3 = session.store.getState().model!.state.messageBox!;
    await ctx.commands.run(session.cmd.answer, { box: box3, cancel: true });
    expect(sim.answers.at(-1)).toEqual({ seq: box3.seq, cancelled: true, value: null });
    sim.raiseMessageBox(7);
    await until(() => session.store.getState().model?.state.messageBox?.mode === 7);
    const box7 = session.store.getState().model!.state.messageBox!;
    await ctx.commands.run(session.cmd.answer, { box: box7, value: 'say "hi"' });
    expect(sim.answers.at(-1)?.value).toBe('say "hi"');
  });

  it('lists files, reads file info with thumbnails and the height map', async () => {
    session.start();
    await until(() => snap().link === 'online');
    // On-demand reads are queries of the machine (reads.ts), no longer fields of the store.
    const entries = await session.loadDir('0:/macros');
    expect(session.store.getState().filesDir).toBe('0:/macros');
    expect(entries.map((e) => e.name)).toEqual(['Filament', 'Heat bed 60C.g', 'Park head.g']);
    const info = await session.loadFileInfo('0:/gcodes/bracket.gcode');
    expect(info.thumbnails[0]?.format).toBe('png');
    expect(ctx.queries.peek<typeof info>(fileInfoKey('0:/gcodes/bracket.gcode'))).toBe(info);
    const map = await session.loadHeightMap();
    expect(map.xnum).toBe(7);
    await ctx.commands
      .run(session.cmd.move, { from: '0:/macros/Park head.g', to: '0:/macros/Heat bed 60C.g' })
      .catch((e: Error) => {
        expect(e.message).toMatch(/409/);
      });
    expect(sim.fs.exists('0:/macros/Park head.g')).toBe(true);
  });
});

describe('messageBoxReply', () => {
  const box = {
    mode: 4,
    seq: 9,
    axisControls: 0,
    cancelButton: false,
    choices: ['a', 'b'],
    default: 0,
    max: null,
    min: null,
    message: '',
    timeout: 0,
    title: '',
  };
  it('formats M292', () => {
    expect(messageBoxReply(box, false, 1)).toBe('M292 P0 S9 R{1}');
    expect(messageBoxReply({ ...box, mode: 2 }, false)).toBe('M292 P0 S9');
    expect(messageBoxReply(box, true)).toBe('M292 P1 S9');
    expect(messageBoxReply({ ...box, mode: 7 }, false, 'a"b')).toBe('M292 P0 S9 R{"a""b"}');
    expect(messageBoxReply({ ...box, mode: 6 }, false, 0.25)).toBe('M292 P0 S9 R{0.25}');
  });
});
