import { spawnSync } from 'node:child_process';
import path from 'node:path';
import { pathToFileURL } from 'node:url';
import { describe, expect, it } from 'vitest';
import { parseServerArgs, USAGE } from './args';

const root = path.resolve(import.meta.dirname, '..');
const defaultDist = path.join(root, 'dist');

describe('parseServerArgs', () => {
  it('defaults to the project dist/ and no host or port', () => {
    expect(parseServerArgs([])).toEqual({ dist: defaultDist });
  });

  it('reads --host with a name, alone (every interface) and as --host=name', () => {
    expect(parseServerArgs(['--host', '127.0.0.1'])).toEqual({ dist: defaultDist, host: '127.0.0.1' });
    expect(parseServerArgs(['--host=0.0.0.0'])).toEqual({ dist: defaultDist, host: '0.0.0.0' });
    expect(parseServerArgs(['--host'])).toEqual({ dist: defaultDist, host: true });
    expect(parseServerArgs(['--host', 'true'])).toEqual({ dist: defaultDist, host: true });
    expect(parseServerArgs(['--host=true'])).toEqual({ dist: defaultDist, host: true });
    // `--host` followed by another option takes no value from it.
    expect(parseServerArgs(['--host', '--port', '5000'])).toEqual({
      dist: defaultDist,
      host: true,
      port: 5000,
    });
    expect(parseServerArgs(['--port', '5000', '--host'])).toEqual({
      dist: defaultDist,
      host: true,
      port: 5000,
    });
  });

  it('reads --port n and --port=n, 0 to 65535', () => {
    expect(parseServerArgs(['--port', '0'])).toEqual({ dist: defaultDist, port: 0 });
    expect(parseServerArgs(['--port=65535'])).toEqual({ dist: defaultDist, port: 65535 });
    expect(parseServerArgs(['--port', '4173', '--strictPort'])).toEqual({ dist: defaultDist, port: 4173 });
  });

  it('refuses a port that is not a port number', () => {
    for (const [argv, shown] of [
      [['--port'], 'nothing'],
      [['--port', '--host'], 'nothing'],
      [['--port', 'http'], 'http'],
      [['--port', '65536'], '65536'],
      [['--port=-1'], '-1'],
      [['--port', '1.5'], '1.5'],
    ] as const)
      expect(parseServerArgs(argv)).toEqual({ error: `--port needs a port number, not ${shown}` });
  });

  it('reads --dist and --outDir (as vite preview), resolved, the last one wins', () => {
    expect(parseServerArgs(['--dist', 'build'])).toEqual({ dist: path.resolve('build') });
    expect(parseServerArgs(['--outDir=/srv/console'])).toEqual({ dist: '/srv/console' });
    expect(parseServerArgs(['--dist', '/a', '--outDir', '/b'])).toEqual({ dist: '/b' });
    expect(parseServerArgs(['--dist'])).toEqual({ error: '--dist needs a folder' });
    expect(parseServerArgs(['--outDir', '--port', '1'])).toEqual({ error: '--outDir needs a folder' });
    expect(parseServerArgs(['--dist='])).toEqual({ error: '--dist needs a folder' });
  });

  it('answers --help and -h', () => {
    expect(parseServerArgs(['--help'])).toEqual({ help: true });
    expect(parseServerArgs(['--port', '1', '-h'])).toEqual({ help: true });
  });

  it('refuses unknown options, arguments and short-option groups, naming them as written', () => {
    for (const raw of ['--bogus', '--bogus=1', '-x', '-hx', 'serve', '--', '--Port'])
      expect(parseServerArgs(['--port', '1', raw, '--help'])).toEqual({ error: `unknown option ${raw}` });
  });

  it('reports the first problem in the order given', () => {
    expect(parseServerArgs(['--bogus', '--port', 'x'])).toEqual({ error: 'unknown option --bogus' });
    expect(parseServerArgs(['--port', 'x', '--bogus'])).toEqual({
      error: '--port needs a port number, not x',
    });
  });
});

describe('server/main.ts arguments', () => {
  const tsxLoader = pathToFileURL(path.join(root, 'node_modules', 'tsx', 'dist', 'loader.mjs')).href;
  const run = (args: string[]): ReturnType<typeof spawnSync> =>
    spawnSync(process.execPath, ['--import', tsxLoader, path.join(root, 'server', 'main.ts'), ...args], {
      cwd: root,
      encoding: 'utf8',
      env: { ...process.env, TSX_TSCONFIG_PATH: path.join(root, 'tsconfig.json'), SHOPDECK_LOG: '' },
      timeout: 60_000,
    });

  it('prints the usage for --help and exits 0, without starting', () => {
    const r = run(['--help']);
    expect(r.status).toBe(0);
    expect(r.stdout).toBe(`${USAGE}\n`);
  });

  it('names an unknown option, prints the usage and exits 2', () => {
    const r = run(['--port', '0', '--bogus']);
    expect(r.status).toBe(2);
    expect(r.stderr).toBe(`shopdeck: unknown option --bogus\n${USAGE}\n`);
    expect(r.stdout).toBe('');
  });
});
