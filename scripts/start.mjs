#!/usr/bin/env node
// `npm start`: build the console when the build is missing or older than the sources (and the
// build tools are installed), then run Shopdeck's own server (server/main.ts) in this process,
// so SIGTERM reaches it directly. With `npm ci --omit=dev` there is no Vite: a prebuilt `dist/`
// is served as it is.
//
// What it prints is short: one line for the build (its full output only when it fails), one for
// the SQLite module, then the server's banner, whose last line is the URL to open.
import { spawnSync } from 'node:child_process';
import { existsSync, readdirSync, statSync } from 'node:fs';
import { createRequire } from 'node:module';
import { join } from 'node:path';
import { buildSummary, sqliteLine } from './start-output.mjs';

const root = new URL('..', import.meta.url).pathname;
const built = join(root, 'dist', 'index.html');

function newest(dir) {
  let t = 0;
  for (const e of readdirSync(dir, { withFileTypes: true })) {
    const p = join(dir, e.name);
    t = Math.max(t, e.isDirectory() ? newest(p) : statSync(p).mtimeMs);
  }
  return t;
}

function viteInstalled() {
  try {
    createRequire(import.meta.url).resolve('vite/package.json');
    return true;
  } catch {
    return false;
  }
}

const sourcesTime = Math.max(
  newest(join(root, 'src')),
  newest(join(root, 'public')),
  statSync(join(root, 'index.html')).mtimeMs,
  statSync(join(root, 'package.json')).mtimeMs,
);
const stale = !existsSync(built) || statSync(built).mtimeMs < sourcesTime;
if (stale && viteInstalled()) {
  console.log('Building the console (once, and again when the sources change)…');
  const t0 = Date.now();
  const r = spawnSync('npm', ['run', '--silent', 'build'], {
    cwd: root,
    stdio: ['ignore', 'pipe', 'pipe'],
    encoding: 'utf8',
    maxBuffer: 64 * 1024 * 1024,
  });
  const output = `${r.stdout ?? ''}${r.stderr ?? ''}`;
  if (r.status !== 0) {
    process.stderr.write(output);
    console.error(`The build failed${r.error ? ` (${r.error.message})` : ''}: see above.`);
    process.exit(r.status ?? 1);
  }
  console.log(buildSummary(output, Date.now() - t0));
} else if (!existsSync(built)) {
  console.error(
    'No built console in dist/ and no build tools installed: run `npm install && npm run build`.',
  );
  process.exit(1);
} else if (stale) {
  console.warn(
    'dist/ is older than the sources (no build tools installed to rebuild it): serving it as it is.',
  );
}

const sqlite = sqliteLine(() => {
  const require = createRequire(import.meta.url);
  const Database = require('better-sqlite3');
  new Database(':memory:').close();
  return { version: require('better-sqlite3/package.json').version };
});
if (sqlite.ok) console.log(sqlite.line);
else console.error(sqlite.line);

const { register } = await import('tsx/esm/api');
register();
await import('../server/main.ts');
