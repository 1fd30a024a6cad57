import path from 'node:path';
import { fileURLToPath } from 'node:url';
import { parseArgs, type ParseArgsConfig } from 'node:util';

/** The server's command line (`tsx server/main.ts …`), read by `parseServerArgs`. */

export const USAGE = `usage: tsx server/main.ts [--host [name]] [--port n] [--dist dir]
  --host [name]  listen on this host (default SHOPDECK_HOST, else localhost); alone: every interface
  --port n       listen on this port (default SHOPDECK_PORT, else PORT, else 4173; 0: any free port)
  --dist dir     the built console (default dist/ of the project)`;

const root = fileURLToPath(new URL('..', import.meta.url));

export interface ServerArgs {
  host?: string | true;
  port?: number;
  dist: string;
}

const OPTIONS = {
  help: { type: 'boolean', short: 'h' },
  host: { type: 'string' },
  port: { type: 'string' },
  dist: { type: 'string' },
  outDir: { type: 'string' },
  // Accepted for the command lines written for `vite preview`: this server never moves to another port.
  strictPort: { type: 'boolean' },
} as const satisfies ParseArgsConfig['options'];

const takesNoValue = (next: string | undefined): boolean => next === undefined || next.startsWith('--');

/**
 * node:util `parseArgs` reads the command line; its tokens (in the order given) are checked here so
 * the first problem is the one reported, in this server's words (`unknown option <as written>`).
 * Non-strict mode keeps unknown options and arguments as tokens instead of throwing node's English.
 */
export function parseServerArgs(argv: readonly string[]): ServerArgs | { help: true } | { error: string } {
  // `--host` alone means every interface (as `vite preview --host`); parseArgs has no option with
  // an optional value, so it gets its value here. Any other option never takes one starting `--`.
  const args = argv.map((a, i) => (a === '--host' && takesNoValue(argv[i + 1]) ? '--host=true' : a));
  const { tokens } = parseArgs({
    args,
    options: OPTIONS,
    strict: false,
    allowPositionals: true,
    tokens: true,
  });
  const out: ServerArgs = { dist: path.join(root, 'dist') };
  for (const token of tokens) {
    const raw = argv[token.index] ?? '';
    if (token.kind !== 'option' || !Object.hasOwn(OPTIONS, token.name))
      return { error: `unknown option ${raw}` };
    // A short-option group (`-hx`) is one word on the command line: unknown as a whole.
    if (raw !== token.rawName && !raw.startsWith(`${token.rawName}=`))
      return { error: `unknown option ${raw}` };
    const value = token.inlineValue === false && takesNoValue(token.value) ? undefined : token.value;
    switch (token.name as keyof typeof OPTIONS) {
      case 'help':
        return { help: true };
      case 'host':
        out.host = value === undefined || value === 'true' ? true : value;
        break;
      case 'port': {
        const n = Number(value);
        if (value === undefined || !Number.isInteger(n) || n < 0 || n > 65535)
          return { error: `--port needs a port number, not ${value ?? 'nothing'}` };
        out.port = n;
        break;
      }
      case 'dist':
      case 'outDir':
        if (!value) return { error: `${token.rawName} needs a folder` };
        out.dist = path.resolve(value);
        break;
      case 'strictPort':
        break;
    }
  }
  return out;
}
