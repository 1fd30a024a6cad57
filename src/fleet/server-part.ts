import type { FamilyDescriptor } from './contract';
import type { Simulator } from './sim';
import type { MachineApi, MachineKind, Role } from './types';

/**
 * A family's server part (`src/controllers/<kind>/server/`, Node-only): what the gateway runs for
 * the family besides forwarding requests — a link to a board it owns (a serial port), routes of
 * its own, a pull into the production history, simulated boards for `npm run sim`. Listed once in
 * `src/controllers/families.ts`; the page never imports a `server/` folder (gateway/bundle.test.ts).
 * Types only here: the gateway implements the mechanisms once, a family fills them in.
 */

/** A family as the gateway and `npm run sim` see it: its descriptor and its server part, if any. */
export interface NodeFamily extends FamilyDescriptor {
  server?: FamilyServerPart;
  /** The machines of the built-in demo fleet (all simulated), in the order the fleet shows them. */
  demo?: ReadonlyArray<{ id: string; name: string; api?: MachineApi }>;
  /**
   * The machines-file fields beyond the common ones this family accepts: `serial` (and `baudRate`)
   * for a board the gateway reaches over a serial port, `api` to force one of its APIs.
   */
  machineFields?: ReadonlyArray<'serial' | 'api'>;
  /**
   * Further simulated machines `npm run sim` starts for a family that speaks another API (a Duet
   * without an SBC: standalone `rr_*`). Their machines-file entry has no `api`: the gateway finds
   * out by probing, as it would for a real board.
   */
  simVariants?: ReadonlyArray<{ id: string; label: string; machineApi: MachineApi }>;
}

export interface FamilyServerPart {
  /** Boards the gateway drives itself over a serial port (machines-file `serial`). */
  serial?: SerialPart;
  /** Routes of the family's own, mounted by the gateway at `/api/<name>/<kind>`. */
  routes?: readonly FamilyRoute[];
  /** What the family adds to the production history (gateway/history/). */
  history?: HistoryPart;
  /** A simulated board on a serial port for `npm run sim` (a pseudo-terminal). */
  simSerial?: SimSerialPart;
}

// ---- Serial links -------------------------------------------------------------------------

export interface PortInfo {
  path: string;
  vendorId?: string;
  productId?: string;
}

/** What an opened port offers a link. Writes are whole lines or single controls, in order, as bytes. */
export interface OpenPort {
  write(data: Buffer): void;
  close(): Promise<void>;
}

export interface PortEvents {
  data(chunk: Buffer): void;
  /** The port went away (unplugged, or an error ended it). */
  closed(why: string): void;
}

export interface PortOpener {
  open(path: string, baudRate: number, events: PortEvents): Promise<OpenPort>;
  list(): Promise<PortInfo[]>;
}

export interface SerialPart {
  /**
   * The board of one machine, answered like a simulator (`fetch(req, path)`) so the proxy routes it
   * exactly as one: access control, audit and sharing happen before a request gets here. It owns
   * its port from the start; it is never reset from the dev panel.
   */
  open(o: {
    id: string;
    name: string;
    /** Device path, or "auto". */
    path: string;
    baudRate: number;
    /** How ports are opened (tests: the serialport mock binding); absent: the machine's real ports. */
    opener?: PortOpener;
    /** A board that sends nothing this long while it runs is "stuck in run", ms. */
    watchdogMs: number;
    event(level: 'info' | 'warn' | 'error', message: string): void;
  }): Simulator;
}

export interface SimSerialPart {
  /** Why no simulated serial board can be offered here, or null. */
  unavailable(): string | null;
  start(): Promise<{ path: string; close(): void }>;
  /** Its machines-file entry (without `serial`, which is the device's path) and a line for the console. */
  entry: { id: string; name: string };
  describe: string;
}

// ---- Routes -------------------------------------------------------------------------------

/** Network discovery settings the gateway passes to a discovery route (tests, SHOPDECK_DISCOVERY_*). */
export interface DiscoveryOptions {
  /** Broadcast address (SHOPDECK_DISCOVERY_BROADCAST, default 255.255.255.255). */
  broadcast: string;
  /** UDP port the controllers listen on. */
  udpPort: number;
  /** UDP port we listen on for answers (default: udpPort). */
  listenUdpPort?: number;
  /** TCP port we listen on for answers. */
  tcpPort: number;
  listenMs: number;
  /** Address to bind the listeners to (default all). */
  bindAddress?: string;
}

/**
 * A GET route of a family (`GET /api/<name>/<kind>`). The gateway checks the session (401 without
 * one) and the role (403 with `forbidden` and `needs`) before `handle` runs, and sends its answer
 * as JSON. GET only: it changes nothing, so it needs no CSRF check and no audit entry.
 */
export interface FamilyRoute {
  name: string;
  role: Role;
  /** The 403 message for a user below `role`. */
  forbidden: string;
  handle(o: {
    env: NodeJS.ProcessEnv;
    discovery: Partial<DiscoveryOptions>;
  }): Promise<{ status: number; body: unknown }>;
}

// ---- History ------------------------------------------------------------------------------

/** The log a server part writes to (the gateway's logger). */
export interface PartLog {
  info(msg: string, fields?: Record<string, unknown>): void;
  warn(msg: string, fields?: Record<string, unknown>): void;
  error(msg: string, fields?: Record<string, unknown>): void;
}

/** The days of statistics a controller keeps itself, as the history stores them (`touchcut_days`). */
export interface HistoryDays {
  readonly isClosed: boolean;
  /** Days already stored for a machine from `fromDay` on. */
  held(machine: string, fromDay: string): Set<string>;
  put(machine: string, day: string, stats: unknown, pulledAt: number): void;
}

export interface HistoryPart {
  /**
   * Pulls what the controller keeps (TouchCut's daily statistics) into the history, for the
   * family's machines: started with the history (its own timer), stopped with it; `pullOnce` is
   * also the history's "pull now".
   */
  statsPuller(o: {
    days: HistoryDays;
    machines: ReadonlyArray<{ id: string; name: string; kind: string }>;
    /** The watch's read path (proxy-http.ts `watchRead`): the machine's key or held login. */
    read(
      m: { id: string; name: string; kind: string },
      pathAndQuery: string,
    ): Promise<{ status: number; body: string; gateway?: boolean }>;
    log: PartLog;
    now: () => number;
  }): StatsPuller;
  /**
   * The API's answer for the stored days (`GET /api/history/<route>`, `.csv`): `module` is the URL
   * of a file exporting `statsExport: StatsExport`, which the history's read workers load (the
   * answers are computed off the gateway's thread, where no function can be passed).
   */
  statsExport?: { route: string; module: string };
}

/** How a family's stored days of statistics are exported: the CSV columns they give a day. */
export interface StatsExport {
  /** Columns between `day` and `pulled` (`sessions`, `active_s`, …). */
  columns: readonly string[];
  /** Those columns of one stored day (null where the stored value says nothing). */
  row(stats: unknown): ReadonlyArray<string | number | null>;
}

export interface StatsPuller {
  start(): void;
  stop(): void;
  pullOnce(): Promise<{ stored: number; failed: number }>;
}

/** The kinds whose family declares `field` in its machines-file fields. */
export function kindsAccepting(
  families: Partial<Record<MachineKind, NodeFamily>>,
  field: 'serial' | 'api',
): MachineKind[] {
  return Object.values(families)
    .filter((f): f is NodeFamily => !!f && (f.machineFields ?? []).includes(field))
    .map((f) => f.kind);
}
