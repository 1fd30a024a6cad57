import { SerialPort, SerialPortMock } from 'serialport';
import type { SerialPortStream } from '@serialport/stream';
import type { OpenPort, PortEvents, PortInfo, PortOpener } from './link';

/**
 * Port openers for the serial link: the real one (`serialport`'s native binding) and one on the
 * library's mock binding for tests. Both wrap a `SerialPortStream`: exclusive open (`lock`), data,
 * and the `close` event the stream emits when the device disappears.
 */

type Make = (path: string, baudRate: number) => SerialPortStream;

function streamOpener(make: Make, list: () => Promise<PortInfo[]>): PortOpener {
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
              port.write(data, 'latin1');
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

/** The machine's real serial ports. */
export function nativeOpener(): PortOpener {
  return streamOpener(
    (path, baudRate) => new SerialPort({ path, baudRate, autoOpen: false, lock: true }),
    async () =>
      (await SerialPort.list()).map((p) => ({ path: p.path, vendorId: p.vendorId, productId: p.productId })),
  );
}

/**
 * The mock binding's ports (tests): create them with `SerialPortMock.binding.createPort`.
 * `opened` sees each stream once it is open (to attach a simulated board to its binding).
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
