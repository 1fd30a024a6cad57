import type { SerialPortStream } from '@serialport/stream';
import type { OpenPort, PortEvents, PortInfo, PortOpener } from './link';

/**
 * Port openers for the serial link: the real one (`serialport`'s native binding) and one on the
 * library's mock binding for tests. Both wrap a `SerialPortStream`: exclusive open (`lock`), data,
 * and the `close` event the stream emits when the device disappears.
 */

export type Make = (path: string, baudRate: number) => SerialPortStream;

export function streamOpener(make: Make, list: () => Promise<PortInfo[]>): PortOpener {
  return {
    list,
    open(path: string, baudRate: number, events: PortEvents): Promise<OpenPort> {
      const port = make(path, baudRate);
      return new Promise<OpenPort>((resolve, reject) => {
        port.open((err) => {
          if (err) {
            reject(err);
            return;
          }
          let closing = false;
          port.on('data', (chunk: Buffer) => events.data(chunk));
          port.on('error', (e: Error) => {
            if (!closing) events.closed(e.message);
          });
          port.on('close', (e: (Error & { disconnected?: boolean }) | null) => {
            if (!closing) events.closed(e?.disconnected ? 'unplugged' : (e?.message ?? 'closed'));
          });
          resolve({
            write: (data) => {
              port.write(data);
            },
            close: () =>
              new Promise<void>((done) => {
                closing = true;
                if (!port.isOpen) {
                  done();
                  return;
                }
                port.close(() => done());
              }),
          });
        });
      });
    },
  };
}

/**
 * The machine's real serial ports. `serialport` (and its native binding) is loaded on first use,
 * so a gateway without serial machines never loads it.
 */
export function nativeOpener(): PortOpener {
  const lib = import('serialport');
  let opener: PortOpener | null = null;
  const get = async (): Promise<PortOpener> => {
    if (opener) return opener;
    const { SerialPort } = await lib;
    opener = streamOpener(
      (path, baudRate) => new SerialPort({ path, baudRate, autoOpen: false, lock: true }),
      async () =>
        (await SerialPort.list()).map((p) => ({
          path: p.path,
          vendorId: p.vendorId,
          productId: p.productId,
        })),
    );
    return opener;
  };
  void lib.catch(() => undefined);
  return {
    list: async () => (await get()).list(),
    open: async (path, baudRate, events) => (await get()).open(path, baudRate, events),
  };
}
