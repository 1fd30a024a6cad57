import { SerialPortMock } from 'serialport';
import { BoardSim, type BoardSimOptions } from './board-sim';
import { streamOpener } from './ports';
import type { PortOpener } from './link';

/**
 * Test helper: a SIMULATED board (board-sim.ts) on the far end of a `serialport` mock-binding
 * port. Bytes the gateway writes reach `board.receive`; the board's lines arrive as port data.
 * `unplug()` ends the stream as a vanished device does; `replug()` lets it be opened again.
 */
export interface MockBoard {
  board: BoardSim;
  opener: PortOpener;
  /** The current open port, if any. */
  port(): SerialPortMock | null;
  unplug(): void;
  replug(): void;
  /** Makes the port look held by another program (the mock binding's lock). */
  holdByOther(): void;
  release(): void;
}

export function mockBoard(
  path: string,
  opts: BoardSimOptions & { vendorId?: string; productId?: string; bannerOnOpen?: boolean } = {},
): MockBoard {
  const binding = SerialPortMock.binding;
  const create = (): void =>
    binding.createPort(path, {
      echo: false,
      record: false,
      vendorId: opts.vendorId,
      productId: opts.productId,
    });
  create();
  const board = new BoardSim(opts);
  let current: SerialPortMock | null = null;
  let other: SerialPortMock | null = null;
  const opener = mockOpener((port) => {
    current = port;
    const pb = port.port as unknown as {
      write(b: Buffer): Promise<void>;
      emitData(b: Buffer): void;
      isOpen: boolean;
    };
    const write = pb.write.bind(pb);
    pb.write = async (b: Buffer) => {
      await write(b);
      board.receive(Buffer.from(b));
    };
    board.connect((line) => {
      if (pb.isOpen && current === port) pb.emitData(Buffer.from(line + '\n', 'utf8'));
    });
    board.boot(opts.bannerOnOpen !== false);
  });
  return {
    board,
    opener,
    port: () => current,
    unplug() {
      const p = current;
      current = null;
      board.powerOff();
      binding.reset();
      if (p) {
        const err = Object.assign(new Error('device disconnected'), { disconnected: true });
        // What the stream does when a read fails because the device went away.
        (p as unknown as { _disconnected(e: Error): void })._disconnected(err);
      }
    },
    replug() {
      create();
    },
    holdByOther() {
      other = new SerialPortMock({ path, baudRate: 115200, autoOpen: false });
      other.open();
    },
    release() {
      other?.close();
      other = null;
    },
  };
}

/**
 * The mock binding's ports: create them with `SerialPortMock.binding.createPort`. `opened` sees
 * each stream once it is open (to attach a simulated board to its binding).
 */
export function mockOpener(opened?: (port: SerialPortMock) => void): PortOpener {
  return streamOpener(
    (path, baudRate) => {
      const port = new SerialPortMock({ path, baudRate, autoOpen: false });
      if (opened) port.once('open', () => opened(port));
      return port;
    },
    async () =>
      (await SerialPortMock.list()).map((p) => ({
        path: p.path,
        vendorId: p.vendorId,
        productId: p.productId,
      })),
  );
}
