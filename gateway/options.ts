import type { MachineKind } from '../src/fleet/types';
import type { DiscoveryOptions, NodeFamily, PortOpener } from '../src/fleet/server-part';
import type { AuditLogOptions } from './audit';
import type { IdleTimeouts, RateLimitOptions } from './auth';
import type { Logger } from './log';
import type { MachinesConfig } from './machines';
import type { UpstreamLimits } from './upstream-types';

/** How a gateway is made (`createGateway`, `createContext`): files, clocks, limits, the families. */

export type Families = Partial<Record<MachineKind, NodeFamily>>;

export interface GatewayOptions {
  /** How serial machines' ports are opened (tests: the serialport mock binding). Default: the real ports. */
  serialOpener?: PortOpener;
  /**
   * A serial board that sends nothing this long while it runs is "stuck in run", ms (default
   * 10 s; SHOPDECK_SERIAL_WATCHDOG_S).
   */
  serialWatchdogMs?: number;
  /** Open mode served beyond this computer (SHOPDECK_OPEN=1): the page's banner says so. */
  openOnNetwork?: boolean;
  machinesFile?: string;
  dataDir?: string;
  usersFile?: string;
  env?: NodeJS.ProcessEnv;
  cwd?: string;
  /** Already loaded machines (the plugin validates at config time). */
  machines?: MachinesConfig;
  /** The family registry (src/controllers/families.ts). */
  families: Families;
  /** Clock for sessions, rate limits, elevation and the windows of shared reads (tests). */
  now?: () => number;
  /** Per-request timeout towards a controller, ms (default 15 s; SHOPDECK_PROXY_TIMEOUT_MS). */
  timeoutMs?: number;
  /** Idle timeouts per role, seconds (SHOPDECK_IDLE_<ROLE>_S). */
  idleTimeoutS?: Partial<IdleTimeouts>;
  /** How long a PIN elevation lasts, seconds (SHOPDECK_ELEVATION_S). */
  elevationS?: number;
  rateLimit?: Partial<RateLimitOptions>;
  discovery?: Partial<DiscoveryOptions>;
  /**
   * Host names the console may be reached by (DNS rebinding protection, as Vite's
   * `server.allowedHosts`): `true` for any; IP addresses and localhost are always allowed.
   */
  allowedHosts?: true | readonly string[];
  /** Where the gateway's log lines go (default: `SHOPDECK_LOG=json` or text, stdout/stderr). */
  log?: Logger;
  /**
   * The audit log (tests): retention defaults to `SHOPDECK_AUDIT_DAYS` (400),
   * `SHOPDECK_AUDIT_REFUSAL_DAYS` (30) and `SHOPDECK_AUDIT_REFUSAL_MAX` (100,000).
   */
  audit?: Omit<AuditLogOptions, 'role'>;
  /** Bounds of the shared upstream (upstream-http.ts; tests): queue, kept answers, sizes. */
  upstream?: Partial<UpstreamLimits>;
  /**
   * The gateway's own slow watch of every machine (watch.ts), with or without a viewer. On
   * unless false (gateway tests that count every request to a controller turn it off).
   */
  watch?: boolean;
}
