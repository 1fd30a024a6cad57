import { afterEach, describe, expect, it } from 'vitest';
import { G2coreSerialBridge } from './bridge';
import { nativeOpener } from './ports';
import { ptyUnavailable, startPtyBoard, type PtyBoard } from './pty-board';

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
    const read = pty.board.received.slice(3);
    expect(read).toEqual(lines.slice(0, read.length));
    expect(pty.board.maxPending).toBeLessThanOrEqual(4);
    expect((await call(bridge, 'GET', '/job/1')).body).toMatchObject({ state: 'killed' });
  });
});
