import { afterEach, beforeEach, describe, expect, it, vi } from 'vitest';
import { SerialPortMock } from 'serialport';
import { G2coreSerialBridge } from './bridge';
import { mockBoard, type MockBoard } from './test-board';
import type { BoardSimOptions } from './board-sim';

/**
 * The gateway's serial g2core against a SIMULATED board on the serialport mock binding: the REST
 * design answered from the wire protocol, a 200-line job streamed with a hold, a resume and a
 * kill (exact bytes checked), and the link states (unplugged, port held, reset, stuck in run).
 */

const PATH = '/dev/ttyTEST0';
let events: string[] = [];

function setup(
  opts: BoardSimOptions & {
    vendorId?: string;
    productId?: string;
    serial?: string;
    bannerOnOpen?: boolean;
  } = {},
): {
  mb: MockBoard;
  bridge: G2coreSerialBridge;
} {
  const mb = mockBoard(PATH, opts);
  const bridge = new G2coreSerialBridge({
    id: 'mill',
    name: 'Mill',
    serial: opts.serial ?? PATH,
    baudRate: 115200,
    opener: mb.opener,
    watchdogMs: 10_000,
    events: { event: (level, m) => events.push(`${level}: ${m}`) },
  });
  return { mb, bridge };
}

async function call(
  bridge: G2coreSerialBridge,
  method: string,
  path: string,
  body?: unknown,
): Promise<{ status: number; body: unknown }> {
  const req = new Request(`http://mill.serial${path}`, {
    method,
    body: body === undefined ? undefined : JSON.stringify(body),
    headers: body === undefined ? {} : { 'content-type': 'application/json' },
  });
  const res = await bridge.fetch(req, path);
  const text = await res.text();
  return { status: res.status, body: text ? (JSON.parse(text) as unknown) : null };
}

/** Bytes the gateway wrote, as one string. */
function wire(bridge: G2coreSerialBridge): string {
  return bridge.link.written.join('');
}

/** What the gateway wrote, without the status requests that ask a quiet board whether it lives. */
function writtenBut(bridge: G2coreSerialBridge, from = 0): string[] {
  return bridge.link.written.slice(from).filter((w) => w !== '{"sr":null}\n');
}

async function online(bridge: G2coreSerialBridge): Promise<void> {
  for (let i = 0; i < 50 && !bridge.link.online; i++) await vi.advanceTimersByTimeAsync(100);
  expect(bridge.link.state.state).toBe('online');
}

const JOB = Array.from({ length: 200 }, (_, i) => `G1 X${i + 1} F1000`);

beforeEach(() => {
  vi.useFakeTimers();
  events = [];
  SerialPortMock.binding.reset();
});

afterEach(() => {
  vi.useRealTimers();
  SerialPortMock.binding.reset();
});

describe('serial g2core bridge', () => {
  it('connects: reads the banner, sends the setup, answers /version and /status_report', async () => {
    const { bridge } = setup();
    await online(bridge);
    expect(bridge.link.written.slice(0, 3)).toEqual(['{"sv":1}\n', '{"si":250}\n', '{"sr":null}\n']);
    expect(events).toContain(`info: Mill: online on ${PATH} (set up: sv 1, si 250, sr null)`);
    const v = await call(bridge, 'GET', '/version');
    expect(v.status).toBe(200);
    expect(v.body).toMatchObject({ fb: 101.03, hp: 'ArduinoDue', hv: 'na', msg: 'SYSTEM READY' });
    const sr = await call(bridge, 'GET', '/status_report');
    expect(sr.body).toMatchObject({ stat: 1, posx: 0 });
    const changed = await call(
      bridge,
      'GET',
      `/status_report?filter=${encodeURIComponent('{"stat":1,"posx":5}')}`,
    );
    expect(changed.body).toEqual({ posx: 0 });
    bridge.dispose();
  });

  it('a board that does not reset when the port opens (no banner): /version comes from the sys group', async () => {
    const { bridge } = setup({ bannerOnOpen: false, firmware: '100.26' });
    await online(bridge);
    expect(bridge.link.banner).toBeNull();
    const v = await call(bridge, 'GET', '/version');
    expect(v).toEqual({
      status: 200,
      body: {
        fv: 0.99,
        fb: 100.26,
        fbs: '',
        fbc: 'settings_default.h',
        hp: 3,
        hv: 0,
        id: '0084-084a-29c6-8ce',
      },
    });
    expect(bridge.link.written).toContain('{"sys":null}\n');
    bridge.dispose();
  });

  it('on 100.26 the banner has numbers for hp and hv; TinyG footers have 4 elements and still read f[1]', async () => {
    const a = setup({ firmware: '100.26' });
    await online(a.bridge);
    expect((await call(a.bridge, 'GET', '/version')).body).toMatchObject({ fb: 100.26, hp: 3, hv: 0 });
    a.bridge.dispose();
    SerialPortMock.binding.reset();
    const b = setup({ firmware: 'tinyg' });
    await online(b.bridge);
    const r = await call(b.bridge, 'PUT', '/machine/x/vm', 5000);
    expect(r).toEqual({ status: 200, body: { value: 5000 } });
    const bad = await call(b.bridge, 'GET', '/machine/nosuchkey');
    expect(bad.status).toBe(404);
    expect(bad.body).toMatchObject({ status: { code: 100 } });
    b.bridge.dispose();
  });

  it('streams a 200-line job with a hold, a resume and a kill: exact bytes, never more than 4 lines in flight', async () => {
    const { mb, bridge } = setup({ msPerLine: 50, plannerSize: 28 });
    await online(bridge);
    const before = bridge.link.written.length;
    const posted = await call(bridge, 'POST', '/job', { name: 'part.nc', gcode: JOB.join('\n') });
    expect(posted).toEqual({ status: 201, body: 1 });
    expect(bridge.link.written.length).toBe(before); // queued, not started
    const started = await call(bridge, 'PUT', '/job/1', { state: 'run' });
    expect(started.body).toMatchObject({ state: 'running', lines: 200 });

    await vi.advanceTimersByTimeAsync(2000);
    const running = (await call(bridge, 'GET', '/job/1')).body as { done: number; state: string };
    expect(running.state).toBe('running');
    expect(running.done).toBeGreaterThan(20);
    expect(running.done).toBeLessThan(200);

    expect((await call(bridge, 'PUT', '/job/1', { state: 'pause' })).body).toMatchObject({ state: 'paused' });
    await vi.advanceTimersByTimeAsync(3000);
    expect((await call(bridge, 'GET', '/status_report')).body).toMatchObject({ stat: 6 });
    const heldAt = writtenBut(bridge).length;
    await vi.advanceTimersByTimeAsync(3000);
    expect(writtenBut(bridge).length).toBe(heldAt); // nothing fed while held (a held board is asked whether it lives)

    expect((await call(bridge, 'PUT', '/job/1', { state: 'run' })).body).toMatchObject({ state: 'running' });
    await vi.advanceTimersByTimeAsync(1500);
    expect((await call(bridge, 'PUT', '/job/1', { state: 'kill' })).body).toMatchObject({ state: 'killed' });
    await vi.advanceTimersByTimeAsync(1000);

    const job = (await call(bridge, 'GET', '/job/1')).body as {
      state: string;
      done: number;
      error: { code: number };
    };
    expect(job.state).toBe('killed');
    expect(job.error.code).toBe(207);
    expect((await call(bridge, 'GET', '/status_report')).body).toMatchObject({ stat: 4 });

    // The exact bytes after the setup: job lines in order, each once, with "!" then "~" between
    // two lines, and "!%^D" at a line start; nothing after the kill.
    const after = writtenBut(bridge, 3);
    const controls = after.filter((w) => !w.endsWith('\n'));
    expect(controls).toEqual(['!', '~', '!', '%', '\x04']);
    const lines = after.filter((w) => w.endsWith('\n')).map((w) => w.slice(0, -1));
    expect(lines).toEqual(JOB.slice(0, lines.length));
    expect(lines.length).toBeLessThan(200);
    const text = wire(bridge);
    for (const c of ['!', '~', '%', '\x04']) {
      let i = text.indexOf(c);
      while (i >= 0) {
        // At a line start: after a newline, another control, or first.
        expect(['\n', '!', '~', '%', '\x04', undefined]).toContain(text[i - 1]);
        i = text.indexOf(c, i + 1);
      }
    }
    expect(after[after.length - 1]).toBe('\x04');
    // Flow control: at most 4 lines in flight; the board never had more than 4 unread lines.
    expect(bridge.link.maxInFlight).toBeLessThanOrEqual(4);
    expect(mb.board.maxPending).toBeLessThanOrEqual(4);
    // The board read the lines in the same order (no line duplicated or skipped).
    const read = mb.board.received.slice(3).filter((l) => l !== '{"sr":null}');
    expect(read).toEqual(JOB.slice(0, read.length));
    expect(mb.board.controls).toEqual(['!', '~', '!', '%', '\x04']);
    expect(events.some((e) => /job 1 "part.nc" killed/.test(e))).toBe(true);
    bridge.dispose();
  });

  it('runs a job to the end: done when the last line is answered and the board stops', async () => {
    const { bridge } = setup({ msPerLine: 10 });
    await online(bridge);
    await call(bridge, 'POST', '/job', {
      name: 'short.nc',
      gcode: '(header!)\n%\nG90\nG1 X5 F100 ; go\nG1 X10\n%',
    });
    const op = await call(bridge, 'POST', '/operation', { optype: 'sendfile', value: 1 });
    expect(op.status).toBe(201);
    await vi.advanceTimersByTimeAsync(3000);
    expect((await call(bridge, 'GET', '/job/1')).body).toMatchObject({ state: 'done', done: 3, lines: 3 });
    // Comments and "%" delimiters never reach the board.
    expect(writtenBut(bridge, 3)).toEqual(['G90\n', 'G1 X5 F100\n', 'G1 X10\n']);
    expect((await call(bridge, 'GET', '/status_report')).body).toMatchObject({ stat: 3, posx: 10 });
    bridge.dispose();
  });

  it('uploads a job as multipart, kills a queued job (kept as killed), deletes a finished one', async () => {
    const { bridge } = setup();
    await online(bridge);
    const form = new FormData();
    form.append('file', new Blob(['G0 X1\nG0 X2\n']), 'a.nc');
    const res = await bridge.fetch(
      new Request('http://mill.serial/job', { method: 'POST', body: form }),
      '/job',
    );
    expect(res.status).toBe(201);
    await call(bridge, 'POST', '/job', { name: 'b.nc', gcode: 'G0 X3' });
    expect((await call(bridge, 'GET', '/job')).body).toMatchObject([
      { id: 1, name: 'a.nc', lines: 2, position: 0 },
      { id: 2, name: 'b.nc', lines: 1, position: 1 },
    ]);
    expect((await call(bridge, 'PUT', '/job/1', { state: 'kill' })).body).toMatchObject({ state: 'killed' });
    expect((await call(bridge, 'GET', '/job/1')).body).toMatchObject({ state: 'killed', position: null });
    expect((await call(bridge, 'GET', '/job/2')).body).toMatchObject({ position: 0 });
    expect((await call(bridge, 'DELETE', '/job/1')).status).toBe(204);
    expect((await call(bridge, 'GET', '/job/1')).status).toBe(404);
    // Nothing of either job reached the board.
    expect(bridge.link.written.slice(3)).toEqual([]);
    bridge.dispose();
  });

  it('a hostile board: noise, an endless line, a flood of report keys, nested values and markup are contained', async () => {
    const { mb, bridge } = setup();
    await online(bridge);
    const emit = (text: string): void =>
      (mb.port()!.port as unknown as { emitData(b: Buffer): void }).emitData(Buffer.from(text, 'latin1'));
    emit('\u0000\u00ff\u00fe garbage\n');
    emit('x'.repeat(40_000)); // no newline: dropped, not kept
    const flood = Object.fromEntries(Array.from({ length: 500 }, (_, i) => [`k${i}`, i]));
    emit(
      JSON.stringify({
        sr: { ...flood, posx: 7, deep: { a: { b: 1 } }, msg: '<img src=x onerror=alert(1)>'.repeat(10) },
      }) + '\n',
    );
    emit(JSON.stringify({ sr: { ['a'.repeat(200)]: 1, stat: 3 } }) + '\n');
    await vi.advanceTimersByTimeAsync(10);
    const sr = (await call(bridge, 'GET', '/status_report')).body as Record<string, unknown>;
    expect(Object.keys(sr).length).toBeLessThanOrEqual(100);
    expect(sr.stat).toBe(3);
    expect(sr).not.toHaveProperty('deep');
    expect(Object.keys(sr).every((k) => k.length <= 16)).toBe(true);
    expect(Object.values(sr).every((v) => typeof v !== 'string' || v.length <= 64)).toBe(true);
    // The link still works: the next request gets its own answer.
    expect(await call(bridge, 'GET', '/machine/x/vm')).toEqual({
      status: 200,
      body: { value: expect.any(Number) },
    });
    bridge.dispose();
  });

  it('refuses a line of 254 bytes or more, and "!" hidden in a setting value, before sending anything', async () => {
    const { bridge } = setup();
    await online(bridge);
    const n = bridge.link.written.length;
    const long = await call(bridge, 'POST', '/operation', {
      optype: 'run',
      value: ['G0 X1', 'G1 X' + '1'.repeat(251)],
    });
    expect(long.status).toBe(413);
    expect(long.body).toMatchObject({ status: { code: 107 } });
    const bang = await call(bridge, 'PUT', '/machine/x/vm', 'fast!');
    expect(bang.status).toBe(400);
    const inject = await call(bridge, 'GET', '/machine/' + encodeURIComponent('xvm":1}\n{"gc":"G0 X9'));
    expect(inject.status).toBe(404);
    const gc = await call(bridge, 'PUT', '/machine/gc', 'G0 X1');
    expect(gc.status).toBe(405);
    expect(bridge.link.written.length).toBe(n);
    // 253 bytes with the terminator is the longest line sent.
    const ok = await call(bridge, 'POST', '/operation', { optype: 'run', value: ['G1 X' + '1'.repeat(248)] });
    expect(ok.status).toBe(201);
    bridge.dispose();
  });

  it('settings cannot change while the machine moves (405/106); the overrides can', async () => {
    const { bridge } = setup({ msPerLine: 200 });
    await online(bridge);
    await call(bridge, 'POST', '/operation', { optype: 'run', value: JOB.slice(0, 20) });
    await vi.advanceTimersByTimeAsync(600);
    expect((await call(bridge, 'PUT', '/machine/x/vm', 100)).status).toBe(405);
    expect(await call(bridge, 'PUT', '/machine/mfo', 0.5)).toEqual({ status: 200, body: { value: 0.5 } });
    bridge.dispose();
  });

  it('unplugged: a job ends in error at its line, requests fail at once (503), nothing is re-sent after the replug', async () => {
    const { mb, bridge } = setup({ msPerLine: 50 });
    await online(bridge);
    await call(bridge, 'POST', '/job', { name: 'part.nc', gcode: JOB.join('\n') });
    await call(bridge, 'PUT', '/job/1', { state: 'run' });
    await vi.advanceTimersByTimeAsync(1000);
    mb.unplug();
    await vi.advanceTimersByTimeAsync(10);
    const sr = await call(bridge, 'GET', '/status_report');
    expect(sr.status).toBe(503);
    expect(sr.body).toMatchObject({ gateway: true });
    expect((sr.body as { error: string }).error).toMatch(/went away|unplugged|not there/);
    const job = (await call(bridge, 'GET', '/job/1')).body as {
      state: string;
      error: { additional_description: string };
    };
    expect(job.state).toBe('error');
    expect(job.error.additional_description).toMatch(/went away.*nothing is re-sent/);
    expect(job.error).toMatchObject({ code: 11, description: 'No such device' });
    const cmd = await call(bridge, 'POST', '/operation', { optype: 'run', value: ['G0 X1'] });
    expect(cmd.status).toBe(503);
    // Still unplugged: retries say the port is not there.
    await vi.advanceTimersByTimeAsync(3000);
    expect(bridge.link.state.state).toBe('unplugged');
    const sentBefore = bridge.link.written.length;
    mb.replug();
    await vi.advanceTimersByTimeAsync(12_000);
    expect(bridge.link.state.state).toBe('online');
    // Only the setup again (and status requests asking whether it lives): no job line replayed.
    expect(bridge.link.written.slice(sentBefore, sentBefore + 3)).toEqual([
      '{"sv":1}\n',
      '{"si":250}\n',
      '{"sr":null}\n',
    ]);
    expect(writtenBut(bridge, sentBefore + 3)).toEqual([]);
    expect((await call(bridge, 'GET', '/status_report')).status).toBe(200);
    bridge.dispose();
  });

  it('a port another program holds shows "held by another program" and connects once it is free', async () => {
    const mb = mockBoard(PATH);
    mb.holdByOther();
    const bridge = new G2coreSerialBridge({
      id: 'mill',
      name: 'Mill',
      serial: PATH,
      baudRate: 115200,
      opener: mb.opener,
    });
    await vi.advanceTimersByTimeAsync(50);
    expect(bridge.link.state.state).toBe('busy');
    const r = await call(bridge, 'GET', '/status_report');
    expect(r.status).toBe(503);
    expect((r.body as { error: string }).error).toMatch(/held by another program/);
    mb.release();
    await vi.advanceTimersByTimeAsync(12_000);
    expect(bridge.link.state.state).toBe('online');
    bridge.dispose();
  });

  it('"auto" picks the port with a g2core USB id; none plugged in reads as unplugged', async () => {
    SerialPortMock.binding.createPort('/dev/ttyS0', { vendorId: '8086', productId: '0001' });
    const { bridge } = setup({ serial: 'auto', vendorId: '1d50', productId: '606d' });
    await online(bridge);
    expect(bridge.link.device).toBe(PATH);
    bridge.dispose();
    SerialPortMock.binding.reset();
    SerialPortMock.binding.createPort('/dev/ttyS0', { vendorId: '8086', productId: '0001' });
    const none = new G2coreSerialBridge({
      id: 'm',
      name: 'M',
      serial: 'auto',
      baudRate: 115200,
      opener: mockBoard('/dev/ttyS9').opener,
    });
    SerialPortMock.binding.reset();
    SerialPortMock.binding.createPort('/dev/ttyS0', { vendorId: '8086', productId: '0001' });
    await vi.advanceTimersByTimeAsync(100);
    expect(none.link.state).toMatchObject({ state: 'unplugged', detail: expect.stringMatching(/no g2core/) });
    none.dispose();
  });

  it('a board reset (new banner) ends the running operation without re-sending it, and the link comes back', async () => {
    const { mb, bridge } = setup({ msPerLine: 50 });
    await online(bridge);
    const op = await call(bridge, 'POST', '/operation', { optype: 'run', value: JOB.slice(0, 50) });
    await vi.advanceTimersByTimeAsync(500);
    const sent = bridge.link.written.length;
    mb.board.receive('\x18'); // the reset button on the board
    await vi.advanceTimersByTimeAsync(2000);
    const o = (await call(bridge, 'GET', `/operation/${String(op.body)}`)).body as {
      opstate: string;
      error: { additional_description: string };
    };
    expect(o.opstate).toBe('error');
    expect(o.error.additional_description).toMatch(/reset/);
    expect(o.error).toMatchObject({ code: 200 });
    expect(bridge.link.state.state).toBe('online');
    expect(bridge.link.written.slice(sent)).toEqual(['{"sv":1}\n', '{"si":250}\n', '{"sr":null}\n']);
    expect(events.some((e) => /board reset/.test(e))).toBe(true);
    bridge.dispose();
  });

  it('watchdog: no report for 10 s while running reads as "stuck in run"; a reset (^X) recovers', async () => {
    const { mb, bridge } = setup({ msPerLine: 100 });
    await online(bridge);
    await call(bridge, 'POST', '/job', { name: 'part.nc', gcode: JOB.join('\n') });
    await call(bridge, 'PUT', '/job/1', { state: 'run' });
    await vi.advanceTimersByTimeAsync(1000);
    mb.board.stuckInRun();
    await vi.advanceTimersByTimeAsync(9000);
    expect((await call(bridge, 'GET', '/status_report')).status).toBe(200);
    await vi.advanceTimersByTimeAsync(2000);
    const sr = await call(bridge, 'GET', '/status_report');
    expect(sr.status).toBe(503);
    expect((sr.body as { error: string }).error).toMatch(/stuck in run.*board\/reset/);
    expect(events.some((e) => e.startsWith('error: the board has sent nothing for 10 s'))).toBe(true);
    // New motion is refused while stuck.
    expect((await call(bridge, 'POST', '/operation', { optype: 'run', value: ['G0 X1'] })).status).toBe(405);
    const reset = await call(bridge, 'POST', '/board/reset');
    expect(reset.status).toBe(200);
    expect(bridge.link.written).toContain('\x18');
    await vi.advanceTimersByTimeAsync(2000);
    expect((await call(bridge, 'GET', '/status_report')).status).toBe(200);
    expect((await call(bridge, 'GET', '/job/1')).body).toMatchObject({ state: 'error' });
    bridge.dispose();
  });

  it('watchdog: a slow move that changes nothing for 10 s is alive (it answers the status request), not stuck', async () => {
    const { bridge } = setup({ msPerLine: 15_000 });
    await online(bridge);
    const op = await call(bridge, 'POST', '/operation', { optype: 'run', value: ['G1 X10 F10', 'G1 X20'] });
    await vi.advanceTimersByTimeAsync(14_000);
    expect(bridge.link.written).toContain('{"sr":null}\n');
    expect(bridge.streamer.stuck).toBeNull();
    expect((await call(bridge, 'GET', '/status_report')).status).toBe(200);
    await vi.advanceTimersByTimeAsync(20_000);
    expect((await call(bridge, 'GET', `/operation/${String(op.body)}`)).body).toMatchObject({
      opstate: 'done',
      line: 2,
    });
    expect(events.some((e) => /stuck/.test(e))).toBe(false);
    bridge.dispose();
  });

  it('reads and writes settings as JSON lines; the 101.03 {"err"} companion line is not taken as an answer', async () => {
    const { bridge } = setup();
    await online(bridge);
    const miss = await call(bridge, 'GET', '/machine/spe');
    expect(miss.status).toBe(404);
    // The companion line came after the 100: the next request still gets its own answer.
    expect(await call(bridge, 'GET', '/machine/x/vm')).toEqual({
      status: 200,
      body: { value: expect.any(Number) },
    });
    const g = await call(
      bridge,
      'GET',
      `/machine?filter=${encodeURIComponent('{"x":{"vm":null},"ct":null}')}`,
    );
    expect(g.body).toEqual({ value: { x: { vm: expect.any(Number) }, ct: 0.1 } });
    expect((await call(bridge, 'GET', '/machine?shallow=true')).body).toMatchObject({
      value: { sys: true, x: true },
    });
    const ro = await call(bridge, 'PUT', '/machine/fb', 1);
    expect(ro.status).toBe(405);
    expect(ro.body).toMatchObject({ status: { code: 104 } });
    expect((await call(bridge, 'GET', '/machine/clear')).status).toBe(200);
    expect(bridge.link.written).toContain('{"clear":null}\n');
    bridge.dispose();
  });

  it('an old build answers "!" with an empty {r}: the stray answer is not counted as a line', async () => {
    const { bridge } = setup({ legacyBangReply: true, msPerLine: 100 });
    await online(bridge);
    const op = await call(bridge, 'POST', '/operation', { optype: 'run', value: JOB.slice(0, 10) });
    await vi.advanceTimersByTimeAsync(3000);
    expect((await call(bridge, 'GET', `/operation/${String(op.body)}`)).body).toMatchObject({
      opstate: 'done',
      line: 10,
    });
    // Idle: a "!" now gets the stray {r} with nothing in flight; the next request still works.
    bridge.link.control('!');
    await vi.advanceTimersByTimeAsync(10);
    expect(await call(bridge, 'GET', '/machine/x/vm')).toEqual({
      status: 200,
      body: { value: expect.any(Number) },
    });
    bridge.dispose();
  });

  // ------------------------------------------------------------------ the board as the firmware is

  it('the board answers JSON ahead of G-code lines waiting in it (as the firmware does): the simulated board itself', async () => {
    const { mb, bridge } = setup({ msPerLine: 1000, plannerSize: 2 });
    await online(bridge);
    // Planner of 2 and 1 s per move: the third and fourth lines wait in the board.
    mb.board.receive('G1 X1\nG1 X2\nG1 X3\nG1 X4\n{"xvm":null}\n');
    expect(mb.board.waiting).toBe(2);
    const seen = mb.board.received.slice(3);
    expect(seen).toEqual(['G1 X1', 'G1 X2', '{"xvm":null}']);
    await vi.advanceTimersByTimeAsync(2500);
    expect(mb.board.received.slice(3)).toEqual(['G1 X1', 'G1 X2', '{"xvm":null}', 'G1 X3', 'G1 X4']);
    bridge.dispose();
  });

  it('a job of 300 lines with the planner full throughout, while pages open, close and read the settings tree: every line once, in order, the job done', async () => {
    const { mb, bridge } = setup({ msPerLine: 50, plannerSize: 28 });
    await online(bridge);
    const lines = Array.from({ length: 300 }, (_, i) => `G1 X${(i % 50) + 1} Y${i} F1000`);
    await call(bridge, 'POST', '/job', { name: 'long.nc', gcode: lines.join('\n') });
    await call(bridge, 'PUT', '/job/1', { state: 'run' });
    await vi.advanceTimersByTimeAsync(2000);
    let readsWhileWaiting = 0;
    for (let page = 0; page < 10; page++) {
      // A page opens: the machine, its settings tree and single keys, and the status report.
      const waiting = mb.board.waiting;
      const [tree, x, vm, sr, jobs] = await Promise.all([
        call(bridge, 'GET', '/machine'),
        call(bridge, 'GET', '/machine/x'),
        call(bridge, 'GET', '/machine/x/vm'),
        call(bridge, 'GET', '/status_report'),
        call(bridge, 'GET', '/job'),
      ]);
      if (waiting > 0) readsWhileWaiting++;
      expect(tree.status).toBe(200);
      expect((tree.body as { value: Record<string, unknown> }).value).toMatchObject({
        x: expect.objectContaining({ vm: expect.any(Number) }),
        sys: expect.any(Object),
      });
      expect(x.body).toMatchObject({ value: { vm: expect.any(Number) } });
      expect(vm).toEqual({ status: 200, body: { value: expect.any(Number) } });
      expect(sr.body).toMatchObject({ stat: 5 });
      expect(jobs.body).toMatchObject([{ state: 'running' }]);
      await vi.advanceTimersByTimeAsync(700);
    }
    expect(readsWhileWaiting).toBeGreaterThan(5); // the planner stayed full: lines waited in the board
    await vi.advanceTimersByTimeAsync(20_000);
    const job = (await call(bridge, 'GET', '/job/1')).body as { state: string; done: number };
    expect(job).toMatchObject({ state: 'done', done: 300 });
    const gcode = mb.board.received.filter((l) => !l.startsWith('{'));
    expect(gcode).toEqual(lines);
    expect(bridge.link.maxInFlight).toBeLessThanOrEqual(4);
    expect(mb.board.maxPending).toBeLessThanOrEqual(4);
    expect(events.filter((e) => /job 1/.test(e))).toEqual([
      'info: job 1 "long.nc" started (300 lines)',
      'info: job 1 "long.nc" done at line 300 of 300',
    ]);
    bridge.dispose();
  });

  it('a hold of 60 s with lines waiting: pages opened during it see Hold at once, read settings, and one resumes the job to its end', async () => {
    const { mb, bridge } = setup({ msPerLine: 50, plannerSize: 28 });
    await online(bridge);
    const lines = Array.from({ length: 200 }, (_, i) => `G1 X${i + 1} F1000`);
    await call(bridge, 'POST', '/job', { name: 'held.nc', gcode: lines.join('\n') });
    await call(bridge, 'PUT', '/job/1', { state: 'run' });
    await vi.advanceTimersByTimeAsync(1500);
    expect((await call(bridge, 'PUT', '/job/1', { state: 'pause' })).body).toMatchObject({ state: 'paused' });
    await vi.advanceTimersByTimeAsync(500);
    expect(mb.board.stat).toBe(6);
    expect(mb.board.waiting).toBeGreaterThan(0); // lines wait in the board throughout the hold
    const gcodeWritten = (): number => bridge.link.written.filter((w) => /^G/.test(w)).length;
    const heldAt = gcodeWritten();
    for (let s = 0; s < 60; s += 5) {
      await vi.advanceTimersByTimeAsync(5000);
      // Every page sees the true state at once: held, online, its settings readable.
      const sr = await call(bridge, 'GET', '/status_report');
      expect(sr).toMatchObject({ status: 200, body: { stat: 6 } });
      if (s === 30) {
        // A page opened in the middle of the hold: the whole tree, then Cycle start from it.
        expect((await call(bridge, 'GET', '/machine')).status).toBe(200);
        expect((await call(bridge, 'GET', '/machine/sys')).status).toBe(200);
        expect((await call(bridge, 'GET', '/job/1')).body).toMatchObject({ state: 'paused' });
      }
    }
    expect(gcodeWritten()).toBe(heldAt); // no G-code line fed while held
    expect(mb.board.waiting).toBeGreaterThan(0);
    expect((await call(bridge, 'PUT', '/job/1', { state: 'run' })).body).toMatchObject({ state: 'running' });
    await vi.advanceTimersByTimeAsync(15_000);
    expect((await call(bridge, 'GET', '/job/1')).body).toMatchObject({ state: 'done', done: 200 });
    expect(mb.board.received.filter((l) => !l.startsWith('{'))).toEqual(lines);
    bridge.dispose();
  });

  it('a board that goes silent while idle reads as not answering within 5 s (asked every few seconds), and online again when it answers', async () => {
    const { mb, bridge } = setup();
    await online(bridge);
    // Idle and quiet (filtered reports send nothing): still known alive, it is asked.
    await vi.advanceTimersByTimeAsync(20_000);
    expect((await call(bridge, 'GET', '/status_report')).status).toBe(200);
    expect(bridge.link.written.filter((w) => w === '{"sr":null}\n').length).toBeGreaterThan(3);
    mb.board.hang();
    await vi.advanceTimersByTimeAsync(5000);
    const r = await call(bridge, 'GET', '/status_report');
    expect(r.status).toBe(503);
    expect(r.body).toMatchObject({
      gateway: true,
      error: expect.stringMatching(/Mill: the board has not answered for [5-7] s/),
    });
    mb.board.unhang();
    await vi.advanceTimersByTimeAsync(3000);
    expect((await call(bridge, 'GET', '/status_report')).status).toBe(200);
    bridge.dispose();
  });

  it('G-code answers that echo the line ({"r":{"gc":…}}) are still G-code answers', async () => {
    const { mb, bridge } = setup({ msPerLine: 20, echoGcode: true });
    await online(bridge);
    await call(bridge, 'POST', '/job', { name: 'e.nc', gcode: JOB.slice(0, 60).join('\n') });
    await call(bridge, 'PUT', '/job/1', { state: 'run' });
    await vi.advanceTimersByTimeAsync(300);
    expect((await call(bridge, 'GET', '/machine/x/vm')).status).toBe(200);
    await vi.advanceTimersByTimeAsync(5000);
    expect((await call(bridge, 'GET', '/job/1')).body).toMatchObject({ state: 'done', done: 60 });
    expect(mb.board.received.filter((l) => !l.startsWith('{'))).toEqual(JOB.slice(0, 60));
    bridge.dispose();
  });

  it("a supervisor's job with a JSON line: it is sent only when the lines before it are answered (the board would run it ahead of them)", async () => {
    const { mb, bridge } = setup({ msPerLine: 200, plannerSize: 2 });
    await online(bridge);
    const gcode = ['G1 X1 F100', 'G1 X2', 'G1 X3', 'G1 X4', '{"xvm":4000}', 'G1 X5'];
    await call(bridge, 'POST', '/job', { name: 'mixed.nc', gcode: gcode.join('\n') });
    await call(bridge, 'PUT', '/job/1', { state: 'run' });
    await vi.advanceTimersByTimeAsync(10);
    // Two lines planned, two waiting in the board: the JSON line is not written yet.
    expect(mb.board.waiting).toBe(2);
    expect(bridge.link.written).not.toContain('{"xvm":4000}\n');
    await vi.advanceTimersByTimeAsync(5000);
    expect((await call(bridge, 'GET', '/job/1')).body).toMatchObject({ state: 'done', done: 6 });
    expect(mb.board.received.filter((l) => l !== '{"sr":null}').slice(2)).toEqual(gcode);
    expect(await call(bridge, 'GET', '/machine/x/vm')).toEqual({ status: 200, body: { value: 4000 } });
    bridge.dispose();
  });

  it('TinyG answers an unknown key without naming it: the request gets its 404 at once, the G-code lines in flight are not taken for it', async () => {
    const { mb, bridge } = setup({ firmware: 'tinyg', msPerLine: 100, plannerSize: 4 });
    await online(bridge);
    await call(bridge, 'POST', '/job', { name: 't.nc', gcode: JOB.slice(0, 30).join('\n') });
    await call(bridge, 'PUT', '/job/1', { state: 'run' });
    await vi.advanceTimersByTimeAsync(250);
    expect(mb.board.waiting).toBeGreaterThan(0);
    const [miss, vm] = await Promise.all([
      call(bridge, 'GET', '/machine/nosuchkey'),
      call(bridge, 'GET', '/machine/x/vm'),
    ]);
    expect(miss.status).toBe(404);
    expect(vm).toEqual({ status: 200, body: { value: expect.any(Number) } });
    await vi.advanceTimersByTimeAsync(5000);
    expect((await call(bridge, 'GET', '/job/1')).body).toMatchObject({ state: 'done', done: 30 });
    bridge.dispose();
  });
});
