import { existsSync, mkdtempSync, readdirSync, readFileSync, rmSync, statSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join, relative, resolve } from 'node:path';
import { build } from 'vite';
import { afterAll, beforeAll, describe, expect, it } from 'vitest';

/**
 * Issue 13: the production bundle carries neither msw nor any simulator. Simulated machines are
 * answered by the gateway's in-process simulators (gateway/context.ts `simulatorFor`), which the
 * page drives through `/api/sim/<id>` (gateway/sim-api.ts); msw is for tests only.
 *
 * The production build (the project's vite.config.ts, as `npm run build` makes it) goes to a
 * temporary folder, not the shared `dist/`. Each marker is a string literal that appears in one
 * simulator's source and nowhere else in the browser's sources (checked below, so a renamed
 * label cannot make this test pass vacuously).
 */

const root = resolve(import.meta.dirname, '../..');

/** Strings of msw's browser code (its worker script, its log prefix, its docs links, its API). */
const MSW_MARKERS = ['mockServiceWorker', 'setupWorker', 'mswjs', '[MSW]', 'x-msw-'];

/** One or more string literals per simulator, with the file that holds them. */
const SIM_MARKERS: Array<{ file: string; text: string }> = [
  // The simulator contract: fault injection.
  { file: 'src/fleet/sim.ts', text: 'Service Unavailable (simulated fault)' },
  { file: 'src/fleet/sim.ts', text: 'simulated dropped connection' },
  { file: 'src/controllers/duet/sim/simulator.ts', text: 'DSF service restart (socket close 1011)' },
  { file: 'src/controllers/duet/sim/files.ts', text: 'bracket.gcode' },
  { file: 'src/controllers/g2core/sim/simulator.ts', text: 'Trip a limit switch (ALARM)' },
  { file: 'src/controllers/g2core/sim/jobs.ts', text: 'demo-pocket.nc' },
  { file: 'src/controllers/prunt/sim/sim.ts', text: 'Server restarts (power blip)' },
  { file: 'src/controllers/touchcut/sim/simulator.ts', text: 'Restart TouchCut (not ready for 8 s)' },
  { file: 'src/controllers/xtool/sim/machine.ts', text: 'Load a demo job (as the vendor app would)' },
];

function allFiles(dir: string): string[] {
  return readdirSync(dir).flatMap((f) => {
    const p = join(dir, f);
    return statSync(p).isDirectory() ? allFiles(p) : [p];
  });
}

/** Browser sources that are neither tests nor simulators (where a marker must not appear). */
function browserSources(): string[] {
  return allFiles(join(root, 'src')).filter(
    (f) =>
      /\.(ts|tsx)$/.test(f) &&
      !/\.test\.tsx?$|\.test-util\.ts$/.test(f) &&
      !/[/\\]sim[/\\]/.test(f) &&
      !/[/\\]src[/\\]fleet[/\\](sim|msw)\.ts$/.test(f) &&
      !/[/\\]testkit\.ts$/.test(f),
  );
}

/** Value imports (not `import type`) of a source file: static, side-effect, re-exports, dynamic. */
const VALUE_IMPORT =
  /^\s*(?:import|export)\s+(?!type\b)(?:[^'";]*?\sfrom\s*)?['"]([^'"]+)['"]|\bimport\(\s*['"]([^'"]+)['"]\s*\)/gm;

function resolveImport(from: string, spec: string): string | null {
  const base = resolve(from, '..', spec);
  for (const c of [base, `${base}.ts`, `${base}.tsx`, join(base, 'index.ts'), join(base, 'index.tsx')])
    if (existsSync(c) && statSync(c).isFile()) return c;
  return null;
}

/** Every module the page loads from `src/app/main.tsx`, with the chain that brings it in. */
function pageModules(): Map<string, string[]> {
  const seen = new Map<string, string[]>();
  const start = join(root, 'src/app/main.tsx');
  const queue: Array<[string, string[]]> = [[start, [relative(root, start)]]];
  while (queue.length) {
    const [file, chain] = queue.shift()!;
    if (seen.has(file)) continue;
    seen.set(file, chain);
    if (!/\.(ts|tsx)$/.test(file)) continue;
    for (const m of readFileSync(file, 'utf8').matchAll(VALUE_IMPORT)) {
      const spec = m[1] ?? m[2] ?? '';
      const target = spec.startsWith('.') ? resolveImport(file, spec) : `package:${spec}`;
      if (target && !seen.has(target))
        queue.push([target, [...chain, target.startsWith('package:') ? spec : relative(root, target)]]);
    }
  }
  return seen;
}

describe('the page’s sources', () => {
  it('import neither msw nor a simulator (nor a family’s Node-only file)', () => {
    const bad = [...pageModules()]
      .filter(([file]) =>
        /^package:msw(\/|$)|[/\\]sim[/\\]|[/\\]fleet[/\\](sim|msw)\.ts$|[/\\](family|families)\.ts$|[/\\]testkit\.ts$/.test(
          file,
        ),
      )
      .map(([, chain]) => chain.join(' → '));
    expect(bad).toEqual([]);
  });
});

describe('the production bundle', () => {
  let outDir = '';
  let texts: Array<{ file: string; text: string }> = [];

  beforeAll(async () => {
    outDir = join(mkdtempSync(join(tmpdir(), 'shopdeck-bundle-')), 'dist');
    await build({ root, logLevel: 'silent', build: { outDir, emptyOutDir: true } });
    texts = allFiles(outDir)
      .filter((f) => /\.(js|mjs|html|css|json|webmanifest)$/.test(f))
      .map((f) => ({ file: relative(outDir, f), text: readFileSync(f, 'utf8') }));
  }, 180_000);

  afterAll(() => {
    if (outDir) rmSync(join(outDir, '..'), { recursive: true, force: true });
  });

  it('was built', () => {
    expect(texts.some((t) => t.file.endsWith('.js'))).toBe(true);
  });

  it('contains no msw: neither its code nor its service worker script', () => {
    const hits = texts.flatMap((t) =>
      MSW_MARKERS.filter((m) => t.text.includes(m)).map((m) => `${t.file}: ${m}`),
    );
    if (existsSync(join(outDir, 'mockServiceWorker.js'))) hits.push('mockServiceWorker.js');
    expect(hits).toEqual([]);
  });

  it('contains no simulator code', () => {
    const hits = texts.flatMap((t) =>
      SIM_MARKERS.filter((m) => t.text.includes(m.text)).map((m) => `${t.file}: ${m.text} (${m.file})`),
    );
    expect(hits).toEqual([]);
  });

  it('checks markers that are really the simulators’ own', () => {
    for (const m of SIM_MARKERS)
      expect(readFileSync(join(root, m.file), 'utf8').includes(m.text), `${m.text} in ${m.file}`).toBe(true);
    const elsewhere = browserSources().flatMap((f) => {
      const text = readFileSync(f, 'utf8');
      return [...SIM_MARKERS.map((m) => m.text), ...MSW_MARKERS]
        .filter((s) => text.includes(s))
        .map((s) => `${relative(root, f)}: ${s}`);
    });
    expect(elsewhere).toEqual([]);
  });
});
