import { spawn, spawnSync, type ChildProcess } from 'node:child_process';
import { BoardSim, type BoardSimOptions } from './board-sim';

/**
 * A SIMULATED board (board-sim.ts) behind a pseudo-terminal pair, so the gateway opens a real
 * device path with the real serial binding (`npm run sim`, the integration test). Node has no
 * pty of its own: a small python3 child (its standard `pty` module) makes the pair, prints the
 * device path, and copies bytes between the pty's master side and its stdin/stdout.
 */

const BRIDGE_PY = `
import os, pty, select, sys, tty
m, s = pty.openpty()
tty.setraw(s)
tty.setraw(m)
os.write(2, (os.ttyname(s) + "\\n").encode())
while True:
    r, _, _ = select.select([m, 0], [], [])
    if m in r:
        try:
            d = os.read(m, 4096)
        except OSError:
            d = b""
        if d:
            os.write(1, d)
    if 0 in r:
        d = os.read(0, 4096)
        if not d:
            break
        os.write(m, d)
`;

export interface PtyBoard {
  /** The device to put in a machines file ("serial"). */
  path: string;
  board: BoardSim;
  close(): void;
}

/** Why no pty can be made here, or null when python3 with its pty module is available. */
export function ptyUnavailable(): string | null {
  if (process.platform === 'win32') return 'Windows has no pseudo-terminals (use a virtual COM port pair)';
  const r = spawnSync('python3', ['-c', 'import pty, tty, select'], { stdio: 'ignore', timeout: 5000 });
  if (r.error) return 'python3 is not installed (it makes the pseudo-terminal pair)';
  if (r.status !== 0) return 'python3 has no usable pty module';
  return null;
}

export function startPtyBoard(opts: BoardSimOptions = {}): Promise<PtyBoard> {
  const child: ChildProcess = spawn('python3', ['-u', '-c', BRIDGE_PY], { stdio: ['pipe', 'pipe', 'pipe'] });
  const board = new BoardSim(opts);
  return new Promise<PtyBoard>((resolve, reject) => {
    let err = '';
    let done = false;
    child.once('error', (e) => {
      if (!done) reject(e);
      done = true;
    });
    child.once('exit', (code) => {
      if (!done) reject(new Error(`the pty helper ended (${code}): ${err.slice(0, 200)}`));
      done = true;
    });
    child.stderr?.on('data', (d: Buffer) => {
      err += d.toString();
      const nl = err.indexOf('\n');
      if (done || nl < 0) return;
      done = true;
      const path = err.slice(0, nl).trim();
      child.stdout?.on('data', (chunk: Buffer) => board.receive(chunk));
      board.connect((line) => {
        child.stdin?.write(line + '\n');
      });
      board.boot();
      resolve({
        path,
        board,
        close: () => {
          board.powerOff();
          child.stdin?.end();
          child.kill();
        },
      });
    });
  });
}
