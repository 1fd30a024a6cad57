import type { FamilyServerPart, PortOpener } from '../../../fleet/server-part';
import { G2coreSerialBridge } from './bridge';
import { nativeOpener } from './ports';
import { ptyUnavailable, startPtyBoard } from './pty-board';

/**
 * The g2core family's server part (Node-only; the page never imports it): a board on a USB serial
 * port driven by the gateway's bridge (issue 19), and a simulated one on a pseudo-terminal for
 * `npm run sim`.
 */

/** The machine's real serial ports, opened on first use (`serialport` loads then). */
let native: PortOpener | null = null;

export const g2coreServer: FamilyServerPart = {
  serial: {
    open: (o) =>
      new G2coreSerialBridge({
        id: o.id,
        name: o.name,
        serial: o.path,
        baudRate: o.baudRate,
        opener: o.opener ?? (native ??= nativeOpener()),
        watchdogMs: o.watchdogMs,
        events: { event: o.event },
      }),
  },
  simSerial: {
    unavailable: ptyUnavailable,
    start: () => startPtyBoard(),
    entry: { id: 'sim-g2core-serial', name: 'CNC router — g2core on serial (simulated board)' },
    describe: 'a simulated g2core board on a pseudo-terminal',
  },
};
