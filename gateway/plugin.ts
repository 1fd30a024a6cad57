import type { Duplex } from 'node:stream';
import type { IncomingMessage } from 'node:http';
import type { Plugin, PreviewServer, ViteDevServer } from 'vite';
import { families } from '../src/controllers/families';
import { createGateway } from './gateway';
import { loadMachines, type MachinesConfig } from './machines';
import { dataDirPath, readUsers, usersFilePath } from './users';

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

  const attach = (server: ViteDevServer | PreviewServer): void => {
    machines ??= loadMachines({ machinesFile: opts.machinesFile, env });
    const isPreview = !('ws' in server);
    const cfg = isPreview ? server.config.preview : server.config.server;
    const allowedHosts =
      cfg.allowedHosts === true
        ? true
        : [...(cfg.allowedHosts ?? []), ...(typeof cfg.host === 'string' ? [cfg.host] : [])];
    const gw = createGateway({ ...opts, env, machines, families, allowedHosts });
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
    config(_config, { command }) {
      if (command !== 'serve') return;
      // Fail early, before the server listens.
      machines = loadMachines({ machinesFile: opts.machinesFile, env });
      const dataDir = dataDirPath({ dataDir: opts.dataDir, env, cwd: process.cwd() });
      readUsers(usersFilePath({ usersFile: opts.usersFile, dataDir, env, cwd: process.cwd() }));
    },
    configureServer(server) {
      attach(server);
    },
    configurePreviewServer(server) {
      attach(server);
    },
  };
}
