import path from 'node:path';
import { fileURLToPath } from 'node:url';
import { loggerFromEnv } from './log';
import { createShopdeckServer, type ShopdeckServer } from './server';

/**
 * `tsx server/main.ts [--host [name]] [--port n] [--dist dir]`: serves the built console
 * (`dist/`, made by `npm run build`; scripts/start.mjs builds it when needed) through the gateway.
 * The flags are those `vite preview` took (`--host` alone: every interface); the environment
 * (`SHOPDECK_HOST`, `SHOPDECK_PORT`, `SHOPDECK_HTTPS`, …) is described in server/server.ts.
 * SIGTERM or SIGINT stops it gracefully, exit code 0, within 5 s.
 */

const USAGE = `usage: tsx server/main.ts [--host [name]] [--port n] [--dist dir]
  --host [name]  listen on this host (default SHOPDECK_HOST, else localhost); alone: every interface
  --port n       listen on this port (default SHOPDECK_PORT, else PORT, else 4173; 0: any free port)
  --dist dir     the built console (default dist/ of the project)`;

const root = fileURLToPath(new URL('..', import.meta.url));

interface Args {
  host?: string | true;
  port?: number;
  dist: string;
}

function parseArgs(argv: readonly string[]): Args | { help: true } | { error: string } {
  const out: Args = { dist: path.join(root, 'dist') };
  for (let i = 0; i < argv.length; i++) {
    const raw = argv[i] ?? '';
    const eq = raw.indexOf('=');
    const flag = eq > 0 ? raw.slice(0, eq) : raw;
    const inline = eq > 0 ? raw.slice(eq + 1) : undefined;
    const value = (): string | undefined => {
      if (inline !== undefined) return inline;
      const next = argv[i + 1];
      if (next === undefined || next.startsWith('--')) return undefined;
      i++;
      return next;
    };
    switch (flag) {
      case '--help':
      case '-h':
        return { help: true };
      case '--host': {
        const v = value();
        out.host = v === undefined || v === 'true' ? true : v;
        break;
      }
      case '--port': {
        const v = value();
        const n = Number(v);
        if (v === undefined || !Number.isInteger(n) || n < 0 || n > 65535)
          return { error: `--port needs a port number, not ${v ?? 'nothing'}` };
        out.port = n;
        break;
      }
      case '--dist':
      case '--outDir': {
        const v = value();
        if (!v) return { error: `${flag} needs a folder` };
        out.dist = path.resolve(v);
        break;
      }
      // Accepted for the command lines written for `vite preview`: this server never moves to another port.
      case '--strictPort':
        break;
      default:
        return { error: `unknown option ${raw}` };
    }
  }
  return out;
}

async function main(): Promise<void> {
  const env = process.env;
  const log = loggerFromEnv(env);
  const args = parseArgs(process.argv.slice(2));
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
