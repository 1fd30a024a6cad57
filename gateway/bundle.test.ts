import { existsSync, readdirSync, readFileSync, statSync } from 'node:fs';
import path from 'node:path';
import { describe, expect, it } from 'vitest';

/**
 * Secrets stay in the gateway: browser code never imports the gateway or the machines/users
 * files (where secrets and password hashes live), and a built `dist/` carries none of them.
 */

function files(dir: string, exts: RegExp): string[] {
  const out: string[] = [];
  for (const e of readdirSync(dir)) {
    const p = path.join(dir, e);
    if (statSync(p).isDirectory()) out.push(...files(p, exts));
    else if (exts.test(e)) out.push(p);
  }
  return out;
}

/** The run after the build (`npm run test:bundle`), or `SHOPDECK_REQUIRE_DIST=1`: dist/ must exist. */
function distRequired(env: NodeJS.ProcessEnv): boolean {
  return env.npm_lifecycle_event === 'test:bundle' || env.SHOPDECK_REQUIRE_DIST === '1';
}

const IMPORT = /(?:import|export)[^'"]*?from\s*['"]([^'"]+)['"]|import\(\s*['"]([^'"]+)['"]\s*\)/g;

describe('no secret reaches the browser bundle', () => {
  it('browser code never imports the gateway, the machines file or the users file', () => {
    const bad: string[] = [];
    for (const f of files(path.resolve('src'), /\.(ts|tsx)$/)) {
      if (/\.test\.tsx?$/.test(f)) continue;
      const text = readFileSync(f, 'utf8');
      for (const m of text.matchAll(IMPORT)) {
        const spec = m[1] ?? m[2] ?? '';
        const target = spec.startsWith('.') ? path.resolve(path.dirname(f), spec) : spec;
        if (
          target.startsWith(path.resolve('gateway')) ||
          /(machines|users)\.json$/.test(spec) ||
          spec === 'bcryptjs'
        ) {
          bad.push(`${path.relative('.', f)} imports ${spec}`);
        }
      }
    }
    expect(bad).toEqual([]);
  });

  it('a built dist/ holds no password hash or users file', (ctx) => {
    const dist = path.resolve('dist');
    if (!existsSync(dist)) {
      // After the build (`npm run test:bundle`, part of `npm test`) a missing dist/ is a failure,
      // never a skip: otherwise the guard never runs in a clean `npm test`. Before it, a skip.
      expect(distRequired(process.env), `${dist} is missing: run \`npm run build\` first`).toBe(false);
      ctx.skip();
      return;
    }
    const hits = files(dist, /\.(js|css|html|json|map|txt)$/).filter((f) => {
      const t = readFileSync(f, 'utf8');
      return /\$2[aby]\$\d\d\$/.test(t) || t.includes('"passwordHash"');
    });
    expect(hits).toEqual([]);
  });
});
