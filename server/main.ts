import { parseServerArgs, USAGE } from './args';
import { loggerFromEnv } from './log';
import { createShopdeckServer, type ShopdeckServer } from './server';

/**
 * `tsx server/main.ts [--host [name]] [--port n] [--dist dir]`: serves the built console
 * (`dist/`, made by `npm run build`; scripts/start.mjs builds it when needed) through the gateway.
 * The flags are those `vite preview` took (`--host` alone: every interface); the environment
 * (`SHOPDECK_HOST`, `SHOPDECK_PORT`, `SHOPDECK_HTTPS`, …) is described in server/server.ts.
 * SIGTERM or SIGINT stops it gracefully, exit code 0, within 5 s.
 */

async function main(): Promise<void> {
  const env = process.env;
  const log = loggerFromEnv(env);
  const args = parseServerArgs(process.argv.slice(2));
  if ('help' in args) {
    console.log(USAGE);
    return;
  }
  if ('error' in args) {
    console.error(`shopdeck: ${args.error}\n${USAGE}`);
    process.exit(2);
  }
  let server: ShopdeckServer;
  try {
    server = createShopdeckServer({ distDir: args.dist, host: args.host, port: args.port, env, logger: log });
    await server.listen();
  } catch (e) {
    log.error(e instanceof Error ? e.message.replace(/^shopdeck: /i, '') : String(e));
    process.exit(1);
  }

  let signalled = false;
  const stop = (signal: NodeJS.Signals): void => {
    // systemd (KillMode=control-group) and `tsx` may both deliver the signal: one stop is enough.
    if (signalled) return;
    signalled = true;
    log.info('stopping', { signal });
    // Whatever happens, the process is gone within 5 s (the audit log was synced before this).
    setTimeout(() => {
      log.warn('stopped by the 5 s limit');
      process.exit(0);
    }, 4900).unref();
    server.close().then(
      () => process.exit(0),
      (e: unknown) => {
        log.error('error while stopping', { error: e instanceof Error ? e.message : String(e) });
        process.exit(1);
      },
    );
  };
  process.on('SIGTERM', stop);
  process.on('SIGINT', stop);
  process.on('uncaughtException', (e) => {
    log.error('crashed', { error: e.stack ?? e.message });
    process.exit(1);
  });
  process.on('unhandledRejection', (e) => {
    log.error('crashed', { error: e instanceof Error ? (e.stack ?? e.message) : String(e) });
    process.exit(1);
  });
}

void main();
