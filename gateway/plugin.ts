import type { Duplex } from 'node:stream';
import type { IncomingMessage } from 'node:http';
import type { Plugin, PreviewServer, ViteDevServer } from 'vite';
import { families } from '../src/controllers/families';
import { createGateway } from './gateway';
import { loadMachines, type MachinesConfig } from './machines';
import { pageHeadersMiddleware } from './page-headers';
import { dataDirPath, readUsers, usersFilePath } from './users';

const LOOPBACK = /^(localhost|127(?:\.\d{1,3}){3}|::1|\[::1\])$/i;

/**
 * Open mode (no users file) lets anyone who reaches the console control every machine. Listening
 * beyond this computer in open mode needs `SHOPDECK_OPEN=1`; otherwise the server refuses to
 * start. Returns whether the console is open AND on the network (the banner says so).
 */
export function openModeExposure(
  host: string | boolean | undefined,
  env: NodeJS.ProcessEnv,
  usersFile: string,
): boolean {
  const loopback = host === undefined || host === false || (typeof host === 'string' && LOOPBACK.test(host));
  if (loopback || readUsers(usersFile) !== null) return false;
  if (env.SHOPDECK_OPEN === '1') return true;
  throw new Error(
    `shopdeck: open mode (no users file at ${usersFile}) on ${host === true ? 'every interface' : String(host)}: ` +
      'anyone on the network could control the machines. Add a user first (npm run user -- add <name> --role supervisor), ' +
      'or set SHOPDECK_OPEN=1 to serve the open console on the network anyway.',
  );
}

export interface ShopdeckGatewayOptions {
  machinesFile?: string;
  dataDir?: string;
  usersFile?: string;
  env?: NodeJS.ProcessEnv;
}

/**
 * The gateway as a Vite plugin, for `vite` (dev) and `vite preview` (the served build): the
 * `/api/*` and `/machines/*` middlewares and the `/machines/*` WebSocket upgrades. The machines
 * file and the users file are validated when the server is configured: a bad file stops it
 * with a message naming the file, the entry and the field. `vite build` does not read them.
 */
export function shopdeckGateway(opts: ShopdeckGatewayOptions = {}): Plugin {
  const env = opts.env ?? process.env;
  let machines: MachinesConfig | null = null;
  const usersFile = (e: NodeJS.ProcessEnv): string => {
    const dataDir = dataDirPath({ dataDir: opts.dataDir, env: e, cwd: process.cwd() });
    return usersFilePath({ usersFile: opts.usersFile, dataDir, env: e, cwd: process.cwd() });
  };

  const attach = (server: ViteDevServer | PreviewServer): void => {
    machines ??= loadMachines({ machinesFile: opts.machinesFile, env });
    const isPreview = !('ws' in server);
    const cfg = isPreview ? server.config.preview : server.config.server;
    const allowedHosts =
      cfg.allowedHosts === true
        ? true
        : [...(cfg.allowedHosts ?? []), ...(typeof cfg.host === 'string' ? [cfg.host] : [])];
    const exposed = openModeExposure(cfg.host, env, usersFile(env));
    const gw = createGateway({ ...opts, env, machines, families, allowedHosts, openOnNetwork: exposed });
    server.middlewares.use(pageHeadersMiddleware(!isPreview));
    server.middlewares.use(gw.handle);
    const http = server.httpServer;
    if (http) {
      http.on('upgrade', (req: IncomingMessage, socket: Duplex, head: Buffer) => {
        gw.upgrade(req, socket, head);
      });
      http.on('close', () => gw.close());
    }
    const where = machines.file ?? 'the built-in demo fleet (no machines file)';
    server.config.logger.info(`  shopdeck gateway: ${machines.machines.length} machines from ${where}`);
  };

  return {
    name: 'shopdeck-gateway',
    config(config, { command, isPreview }) {
      if (command !== 'serve') return;
      // Fail early, before the server listens.
      machines = loadMachines({ machinesFile: opts.machinesFile, env });
      const file = usersFile(env);
      readUsers(file);
      openModeExposure(isPreview ? config.preview?.host : config.server?.host, env, file);
      // No CORS for any origin (Vite allows localhost origins by default): the console answers
      // its own page only.
      return { server: { cors: false }, preview: { cors: false } };
    },
    configureServer(server) {
      attach(server);
    },
    configurePreviewServer(server) {
      attach(server);
    },
  };
}
