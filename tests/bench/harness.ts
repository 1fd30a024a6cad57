/**
 * Shared pieces of the browser and server benchmarks: the production build, the production
 * server as a child process (open mode, a machines file, a free port), the system Chromium.
 */
import { execFileSync, spawn, type ChildProcess } from 'node:child_process';
import { existsSync } from 'node:fs';
import path from 'node:path';
import { pathToFileURL } from 'node:url';
import { chromium, type Browser } from '@playwright/test';

export const root = path.resolve(import.meta.dirname, '..', '..');
/** The built console the server serves (BENCH_DIST: another build, e.g. to compare two). */
export const distDir = process.env.BENCH_DIST ?? path.join(root, 'dist');
const tsxLoader = pathToFileURL(path.join(root, 'node_modules', 'tsx', 'dist', 'loader.mjs')).href;

const log = (msg: string): void => {
  process.stderr.write(`bench: ${msg}\n`);
};

export const sleep = (ms: number): Promise<void> => new Promise((r) => setTimeout(r, ms));

/** Builds the console when dist/ is missing (the build's output goes to stderr). */
export function ensureDist(): void {
  if (existsSync(path.join(distDir, 'index.html'))) return;
  log('dist/index.html is missing: running `npm run build`…');
  try {
    // The build's output goes to stderr: stdout carries only result lines.
    execFileSync('npm', ['run', 'build'], { cwd: root, stdio: ['ignore', 2, 2] });
  } catch {
    /* reported below */
  }
  if (!existsSync(path.join(distDir, 'index.html')))
    throw new Error(
      'dist/index.html is missing and `npm run build` did not make it: build the console first',
    );
}

export interface Server {
  base: string;
  stop(): Promise<void>;
}

export function cleanEnv(): NodeJS.ProcessEnv {
  const env: NodeJS.ProcessEnv = {};
  for (const [k, v] of Object.entries(process.env))
    if (!k.startsWith('SHOPDECK_') && k !== 'PORT') env[k] = v;
  return env;
}

/** The production server as a child process, in open mode (unless `extraEnv` says otherwise), on a free port. */
export function startServer(
  work: string,
  machinesFile: string,
  extraEnv: NodeJS.ProcessEnv = {},
): Promise<Server> {
  const dataDir = path.join(work, 'data');
  const child: ChildProcess = spawn(
    process.execPath,
    [
      '--import',
      tsxLoader,
      path.join(root, 'server', 'main.ts'),
      '--dist',
      distDir,
      '--host',
      '127.0.0.1',
      '--port',
      '0',
    ],
    {
      cwd: work,
      env: {
        ...cleanEnv(),
        TSX_TSCONFIG_PATH: path.join(root, 'tsconfig.json'),
        SHOPDECK_DATA: dataDir,
        SHOPDECK_MACHINES: machinesFile,
        SHOPDECK_LOG: 'json',
        ...extraEnv,
      },
      stdio: ['ignore', 'pipe', 'pipe'],
    },
  );
  const tail: string[] = [];
  let port: number | null = null;
  const exited = new Promise<number | null>((r) => child.once('exit', (code) => r(code)));
  const onLine = (line: string): void => {
    tail.push(line);
    if (tail.length > 50) tail.shift();
    if (port === null && line.startsWith('{')) {
      try {
        const e = JSON.parse(line) as { msg?: unknown; port?: unknown };
        if (e.msg === 'listening' && typeof e.port === 'number') port = e.port;
      } catch {
        /* not a log entry */
      }
    }
  };
  for (const stream of [child.stdout, child.stderr]) {
    if (!stream) continue;
    let rest = '';
    stream.setEncoding('utf8');
    stream.on('data', (chunk: string) => {
      const parts = (rest + chunk).split('\n');
      rest = parts.pop() ?? '';
      for (const l of parts) onLine(l);
    });
  }
  const stop = async (): Promise<void> => {
    if (child.exitCode !== null || child.signalCode !== null) return;
    child.kill('SIGTERM');
    const timer = setTimeout(() => child.kill('SIGKILL'), 6000);
    await exited;
    clearTimeout(timer);
  };
  return new Promise((resolve, reject) => {
    const fail = (why: string): void => {
      clearInterval(poll);
      clearTimeout(timer);
      void stop().then(() => reject(new Error(`${why}:\n${tail.join('\n')}`)));
    };
    const timer = setTimeout(() => fail('the server did not start within 30 s'), 30_000);
    void exited.then((code) => fail(`the server exited (${code})`));
    const poll = setInterval(() => {
      if (port === null) return;
      clearInterval(poll);
      clearTimeout(timer);
      resolve({ base: `http://127.0.0.1:${port}`, stop });
    }, 25);
  });
}

export function chromiumPath(): string | undefined {
  return (
    process.env.PLAYWRIGHT_CHROMIUM_PATH ??
    (existsSync('/usr/bin/chromium') ? '/usr/bin/chromium' : undefined)
  );
}

/** Chromium as the benchmarks launch it (the system one where there is one). */
export const CHROMIUM_ARGS = [
  '--no-sandbox',
  '--disable-gpu',
  '--disable-background-networking',
  '--disable-component-update',
];

/**
 * Chromium for a benchmark: the system one where there is one, with Playwright's own signal
 * handlers off (they would exit before the server is stopped: see `stopOnSignal`).
 */
export function launchChromium(): Promise<Browser> {
  const executablePath = chromiumPath();
  return chromium.launch({
    ...(executablePath ? { executablePath } : {}),
    args: CHROMIUM_ARGS,
    handleSIGINT: false,
    handleSIGTERM: false,
  });
}

/**
 * Ctrl-C or a kill: `cleanup` (stop the server, close the browser, remove temp files), then exit.
 * Returns: stop listening (when the bench is done).
 */
export function stopOnSignal(cleanup: () => Promise<void>): () => void {
  const onSignal = (): void => {
    void cleanup().then(() => process.exit(130));
  };
  process.on('SIGINT', onSignal);
  process.on('SIGTERM', onSignal);
  return () => {
    process.off('SIGINT', onSignal);
    process.off('SIGTERM', onSignal);
  };
}
