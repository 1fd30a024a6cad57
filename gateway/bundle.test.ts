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

const IMPORT =
  /(?:import|export)[^'"]*?from\s*['"]([^'"]+)['"]|import\(\s*['"]([^'"]+)['"]\s*\)|import\s*['"]([^'"]+)['"]/g;

/** A family's server part (`src/controllers/<kind>/server/`) and the Node list of families: Node-only. */
const NODE_ONLY = /[\\/]src[\\/]controllers[\\/](?:[^\\/]+[\\/]server[\\/]|families\.ts$)/;

/** The file an import names, as Vite resolves a relative one (null: a package). */
function resolveImport(from: string, spec: string): string | null {
  if (!spec.startsWith('.')) return null;
  const base = path.resolve(path.dirname(from), spec);
  for (const c of [
    base,
    `${base}.ts`,
    `${base}.tsx`,
    path.join(base, 'index.ts'),
    path.join(base, 'index.tsx'),
  ])
    if (existsSync(c) && statSync(c).isFile()) return c;
  return null;
}

/** Every source file the page loads from its entry, dynamic imports included. */
function pageFiles(entry: string): Set<string> {
  const seen = new Set<string>();
  const todo = [entry];
  for (let f = todo.pop(); f !== undefined; f = todo.pop()) {
    if (seen.has(f)) continue;
    seen.add(f);
    if (!/\.(ts|tsx|js|mjs)$/.test(f)) continue;
    for (const m of readFileSync(f, 'utf8').matchAll(IMPORT)) {
      const target = resolveImport(f, m[1] ?? m[2] ?? m[3] ?? '');
      if (target) todo.push(target);
    }
  }
  return seen;
}

describe('no secret reaches the browser bundle', () => {
  it("the page never loads a family's server part, the Node list of families or the gateway", () => {
    const entry = /<script type="module" src="\/([^"]+)"/.exec(readFileSync('index.html', 'utf8'))?.[1];
    expect(entry).toBeDefined();
    const loaded = [...pageFiles(path.resolve(entry ?? ''))].map((f) => path.relative('.', f));
    // The walk does reach the families' page code (it can see a server part if one were imported).
    expect(loaded.filter((f) => /^src[\\/]controllers[\\/][^\\/]+[\\/]/.test(f)).length).toBeGreaterThan(20);
    const bad = loaded.filter((f) => NODE_ONLY.test(path.resolve(f)) || f.startsWith(`gateway${path.sep}`));
    expect(bad).toEqual([]);
    // And the check can fail: a family's page module importing its server part is seen.
    expect(NODE_ONLY.test(path.resolve('src/controllers/g2core/server/index.ts'))).toBe(true);
  });

  it('browser code never imports the gateway, the machines file or the users file', () => {
    const bad: string[] = [];
    for (const f of files(path.resolve('src'), /\.(ts|tsx)$/)) {
      // Node-only code (a family's server part) may use the gateway's modules.
      if (/\.test\.tsx?$/.test(f) || NODE_ONLY.test(f)) continue;
      const text = readFileSync(f, 'utf8');
      for (const m of text.matchAll(IMPORT)) {
        const spec = m[1] ?? m[2] ?? m[3] ?? '';
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
