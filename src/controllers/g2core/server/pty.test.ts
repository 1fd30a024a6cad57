import type { BoardSim } from './board-sim';
import { afterEach, describe, expect, it } from 'vitest';
import { G2coreSerialBridge } from './bridge';
import { nativeOpener } from './ports';
import { ptyUnavailable, startPtyBoard, type PtyBoard } from './pty-board';

/** The lines the board read, without the status requests that ask a quiet board whether it lives (the setup's sv and si first). */
function boardRead(board: BoardSim): string[] {
  return board.received.filter((l) => l !== '{"sr":null}');
}

/**
 * Integration: the bridge on a real device path (a pseudo-terminal pair made by the test) through
 * `serialport`'s native binding, with a SIMULATED board on the far end. Skipped, with the reason,
 * where no pty can be made. The test waits for states; it never asserts a duration.
 */

const why = ptyUnavailable();
const cleanups: Array<() => void> = [];
afterEach(() => {
  for (const c of cleanups.splice(0).reverse()) c();
});

async function until(check: () => boolean | Promise<boolean>, what: string): Promise<void> {
  for (let i = 0; i < 400; i++) {
    if (await check()) return;
    await new Promise((r) => setTimeout(r, 25));
  }
  throw new Error(`never: ${what}`);
}

async function call(
  b: G2coreSerialBridge,
  method: string,
  path: string,
  body?: unknown,
): Promise<{ status: number; body: unknown }> {
  const res = await b.fetch(
    new Request(`http://pty${path}`, { method, body: body === undefined ? undefined : JSON.stringify(body) }),
    path,
  );
  const text = await res.text();
  return { status: res.status, body: text ? (JSON.parse(text) as unknown) : null };
}

describe.skipIf(why !== null)(`serial g2core on a pseudo-terminal${why ? ` (skipped: ${why})` : ''}`, () => {
  it('connects through the native binding, streams a job with a hold, a resume and a kill', async () => {
    const pty: PtyBoard = await startPtyBoard({ msPerLine: 20 });
    cleanups.push(() => pty.close());
    const bridge = new G2coreSerialBridge({
      id: 'pty',
      name: 'PTY board',
      serial: pty.path,
      baudRate: 115200,
      opener: nativeOpener(),
      bannerWaitMs: 200,
    });
    cleanups.push(() => bridge.dispose());
    await until(() => bridge.link.online, 'online');
    expect((await call(bridge, 'GET', '/status_report')).status).toBe(200);
    const lines = Array.from({ length: 200 }, (_, i) => `G1 X${i + 1} F1000`);
    await call(bridge, 'POST', '/job', { name: 'pty.nc', gcode: lines.join('\n') });
    await call(bridge, 'PUT', '/job/1', { state: 'run' });
    await until(
      async () => ((await call(bridge, 'GET', '/job/1')).body as { done: number }).done >= 20,
      '20 lines',
    );
    expect((await call(bridge, 'PUT', '/job/1', { state: 'pause' })).status).toBe(200);
    await until(() => pty.board.stat === 6, 'held');
    expect((await call(bridge, 'PUT', '/job/1', { state: 'run' })).status).toBe(200);
    await until(() => pty.board.stat === 5, 'running again');
    expect((await call(bridge, 'PUT', '/job/1', { state: 'kill' })).status).toBe(200);
    await until(() => pty.board.stat === 4, 'killed');
    expect(pty.board.controls).toEqual(['!', '~', '!', '%', '\x04']);
    const read = boardRead(pty.board).slice(2);
    expect(read).toEqual(lines.slice(0, read.length));
    expect(pty.board.maxPending).toBeLessThanOrEqual(4);
    expect((await call(bridge, 'GET', '/job/1')).body).toMatchObject({ state: 'killed' });
  });
});

describe.skipIf(why !== null)(
  `serial g2core byte checks on a pseudo-terminal${why ? ` (skipped: ${why})` : ''}`,
  () => {
    /**
     * The attack: characters whose low byte is a control. The port writes one byte per character,
     * so "Ę" (U+0118) would reach the board as ^X (reset), "Ą" (U+0104) as ^D (kill), "ġ" as "!",
     * "ĥ" as "%", "ž" as "~", "Ċ" as a line break. None may reach the board, in a job, an MDI
     * operation or a setting; each is refused with 400 naming the line.
     */
    it('refuses a job, an MDI line and a setting holding a character whose byte is a control; nothing reaches the board', async () => {
      const pty: PtyBoard = await startPtyBoard({ msPerLine: 20 });
      cleanups.push(() => pty.close());
      const bridge = new G2coreSerialBridge({
        id: 'pty',
        name: 'PTY board',
        serial: pty.path,
        baudRate: 115200,
        opener: nativeOpener(),
        bannerWaitMs: 200,
      });
      cleanups.push(() => bridge.dispose());
      await until(() => bridge.link.online, 'online');
      await until(() => boardRead(pty.board).length >= 2, 'the setup read');
      const received = boardRead(pty.board).length;
      const written = bridge.link.written.length;
      for (const ch of ['\u0118', '\u0104', '\u0121', '\u0125', '\u017e', '\u010a', '\u0105', '\u00a0']) {
        const job = await call(bridge, 'POST', '/job', { name: 'x.nc', gcode: `G90\nG0 X1 ${ch} Y2\nG0 X2` });
        expect(job.status, ch).toBe(400);
        expect(job.body).toMatchObject({
          status: {
            code: 101,
            additional_description: expect.stringMatching(/^line 2: .*outside printable ASCII/),
          },
        });
        const mdi = await call(bridge, 'POST', '/operation', {
          optype: 'run',
          value: ['G90', `G0 Y1${ch}X1`],
        });
        expect(mdi.status, ch).toBe(400);
        expect(JSON.stringify(mdi.body)).toMatch(/line 2: /);
        const setting = await call(bridge, 'PUT', '/machine/x/vm', `5${ch}`);
        expect(setting.status, ch).toBe(400);
      }
      expect(
        (await call(bridge, 'POST', '/job', { name: 'x.nc', gcode: 'G0 X1 \u0118' })).body,
      ).toMatchObject({
        status: {
          additional_description:
            'line 1: contains a character outside printable ASCII, U+0118 (the board would read ^X, a board reset)',
        },
      });
      // The last check before the port: a request that bypassed the line checks is not written.
      await expect(bridge.link.request('gc', 'G0 X1 \u0118')).rejects.toThrow(/not written to the board/);
      expect(bridge.link.written.length).toBe(written);
      // Nothing reached the board: no line read, no control acted on, still online and idle.
      await new Promise((r) => setTimeout(r, 200));
      expect(boardRead(pty.board).length).toBe(received);
      expect(pty.board.controls).toEqual([]);
      expect(pty.board.stat).toBe(1);
      expect(bridge.link.online).toBe(true);
      // A clean job still runs, its bytes exactly as written.
      expect((await call(bridge, 'POST', '/job', { name: 'ok.nc', gcode: 'G0 X1\tY2\nG0 X3' })).status).toBe(
        201,
      );
      expect((await call(bridge, 'PUT', '/job/1', { state: 'run' })).status).toBe(200);
      await until(() => boardRead(pty.board).length === received + 2, 'the clean job read');
      expect(boardRead(pty.board).slice(received)).toEqual(['G0 X1\tY2', 'G0 X3']);
    });
  },
);

describe.skipIf(why !== null)(
  `serial g2core pages during a job on a pseudo-terminal${why ? ` (skipped: ${why})` : ''}`,
  () => {
    it('ten pages open and read the settings tree while a 300-line job streams with the planner full: the job ends done, every line once', async () => {
      const pty: PtyBoard = await startPtyBoard({ msPerLine: 8, plannerSize: 28 });
      cleanups.push(() => pty.close());
      const bridge = new G2coreSerialBridge({
        id: 'pty',
        name: 'PTY board',
        serial: pty.path,
        baudRate: 115200,
        opener: nativeOpener(),
        bannerWaitMs: 200,
      });
      cleanups.push(() => bridge.dispose());
      await until(() => bridge.link.online, 'online');
      const lines = Array.from({ length: 300 }, (_, i) => `G1 X${(i % 40) + 1} Y${i} F1000`);
      await call(bridge, 'POST', '/job', { name: 'pty.nc', gcode: lines.join('\n') });
      await call(bridge, 'PUT', '/job/1', { state: 'run' });
      await until(() => pty.board.waiting > 0, 'lines waiting in the board (the planner full)');
      let whileWaiting = 0;
      for (let page = 0; page < 10; page++) {
        const waiting = pty.board.waiting;
        const [tree, key, sr] = await Promise.all([
          call(bridge, 'GET', '/machine'),
          call(bridge, 'GET', '/machine/x/vm'),
          call(bridge, 'GET', '/status_report'),
        ]);
        if (waiting > 0) whileWaiting++;
        expect(tree.status).toBe(200);
        expect(key.status).toBe(200);
        expect(sr.status).toBe(200);
        const job = (await call(bridge, 'GET', '/job/1')).body as { state: string };
        expect(['running', 'done']).toContain(job.state);
      }
      expect(whileWaiting).toBeGreaterThan(0);
      await until(
        async () => ((await call(bridge, 'GET', '/job/1')).body as { state: string }).state !== 'running',
        'the job ended',
      );
      expect((await call(bridge, 'GET', '/job/1')).body).toMatchObject({ state: 'done', done: 300 });
      expect(pty.board.received.filter((l) => !l.startsWith('{'))).toEqual(lines);
      expect(pty.board.maxPending).toBeLessThanOrEqual(4);
    });
  },
);
