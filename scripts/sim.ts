import { writeFileSync } from 'node:fs';
import path from 'node:path';
import { families } from '../src/controllers/families';
import { startSimFleet } from '../gateway/sim-server';

/**
 * `npm run sim [-- --write machines.sim.json] [--base-port 47100] [--host 127.0.0.1]`
 *
 * Starts every registered family's simulator as a real HTTP + WebSocket server on localhost
 * (one port per machine, a second one for the socket where the family has its own WebSocket
 * port), plus each family's `simVariants` (a standalone Duet speaking `rr_*`, whose entry has
 * no `api`: the console probes it), and prints a machines file pointing at them. Run the console against them with
 * `SHOPDECK_MACHINES=machines.sim.json npm start`.
 *
 * It also offers each family's simulated serial board (its server part's `simSerial`; issue 19): a
 * SIMULATED board on a pseudo-terminal pair, whose device path goes into the machines file as
 * `"serial"`, so the console's gateway drives it over the real serial binding as it would a board
 * on USB. `--no-serial` leaves them out; where no pty can be made (no python3, Windows) one line
 * says so.
 */

function arg(name: string): string | undefined {
  const i = process.argv.indexOf(name);
  return i >= 0 ? process.argv[i + 1] : undefined;
}

async function main(): Promise<void> {
  const write = arg('--write');
  const basePort = Number(arg('--base-port') ?? 0);
  const host = arg('--host') ?? '127.0.0.1';
  if (!Number.isInteger(basePort) || basePort < 0 || basePort > 65000)
    throw new Error('--base-port: not a port');
  const fleet = await startSimFleet(families, { host, basePort });
  const machines: Array<Record<string, unknown>> = [...fleet.machinesFile.machines];
  const serials: Array<{ line: string; close(): void }> = [];
  const noSerial: string[] = [];
  for (const fam of Object.values(families)) {
    const part = fam.server?.simSerial;
    if (!part) continue;
    const noPty = process.argv.includes('--no-serial') ? '--no-serial' : part.unavailable();
    if (noPty !== null) {
      noSerial.push(`  no serial ${fam.kind}: ${noPty}`);
      continue;
    }
    const board = await part.start();
    machines.push({ ...part.entry, kind: fam.kind, serial: board.path });
    serials.push({
      line: `  ${part.entry.id.padEnd(16)} serial ${board.path}  (${part.describe})`,
      close: () => board.close(),
    });
  }
  const text = JSON.stringify({ machines }, null, 2) + '\n';
  if (write) {
    const file = path.resolve(write);
    writeFileSync(file, text);
    console.error(`wrote ${file}`);
  }
  console.log(text);
  console.error('Simulated machines (everything here is simulated):');
  for (const s of fleet.servers) {
    console.error(`  ${s.id.padEnd(16)} ${s.url}${s.wsUrl ? `  socket ${s.wsUrl}` : ''}`);
    const controls = s.sim.controls();
    if (controls.length)
      console.error(`  ${''.padEnd(16)} controls: ${controls.map((c) => c.id).join(', ')}`);
  }
  for (const s of serials) console.error(s.line);
  for (const line of noSerial) console.error(line);
  console.error(
    '\nFault injection on each port: POST /__sim/faults {"latencyMs":0,"drop":false,"http5xx":false,"malformed":false},' +
      '\n  POST /__sim/close-sockets, POST /__sim/control/<id>.  Ctrl-C stops.',
  );
  const stop = (): void => {
    for (const s of serials) s.close();
    void fleet.close().then(() => process.exit(0));
  };
  process.on('SIGINT', stop);
  process.on('SIGTERM', stop);
}

main().catch((e: unknown) => {
  console.error(e instanceof Error ? e.message : String(e));
  process.exit(1);
});
