#!/usr/bin/env node
// `npm start`: build the console when the build is missing or older than the sources (and the
// build tools are installed), then run Shopdeck's own server (server/main.ts) in this process,
// so SIGTERM reaches it directly. With `npm ci --omit=dev` there is no Vite: a prebuilt `dist/`
// is served as it is.
import { spawnSync } from 'node:child_process';
import { existsSync, readdirSync, statSync } from 'node:fs';
import { createRequire } from 'node:module';
import { join } from 'node:path';

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
  console.log('Building the console…');
  const r = spawnSync('npm', ['run', '--silent', 'build'], { cwd: root, stdio: 'inherit' });
  if (r.status !== 0) process.exit(r.status ?? 1);
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

const { register } = await import('tsx/esm/api');
register();
await import('../server/main.ts');
