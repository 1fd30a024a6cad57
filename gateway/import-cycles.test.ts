import { readdirSync, readFileSync } from 'node:fs';
import path from 'node:path';
import ts from 'typescript';
import { describe, expect, it } from 'vitest';

/**
 * No import loop among the gateway's modules (issue 34 §2): every static import, `import type`
 * and `export … from` included, read with the TypeScript compiler's own import scanner. The walk
 * goes through every product file of gateway/ (tests aside), so a loop that passes through a
 * folder such as history/ is seen; a loop is refused when gateway/*.ts or gateway/routes/*.ts is
 * on it.
 */

const GATEWAY = path.dirname(new URL(import.meta.url).pathname);

/** The gateway's product files: path relative to gateway/ → source. */
function gatewaySources(dir = GATEWAY): Map<string, string> {
  const out = new Map<string, string>();
  for (const e of readdirSync(dir, { withFileTypes: true, recursive: true })) {
    if (!e.isFile() || !e.name.endsWith('.ts') || e.name.endsWith('.d.ts')) continue;
    if (/\.test\.ts$|(^|\/)test-util\.ts$/.test(e.name)) continue;
    const full = path.join(e.parentPath, e.name);
    out.set(path.relative(dir, full).split(path.sep).join('/'), readFileSync(full, 'utf8'));
  }
  return out;
}

/** The files each file imports (static imports, type-only ones and re-exports), among `sources`. */
function importGraph(sources: ReadonlyMap<string, string>): Map<string, string[]> {
  const graph = new Map<string, string[]>();
  for (const [file, text] of sources) {
    const deps: string[] = [];
    for (const ref of ts.preProcessFile(text, true, false).importedFiles) {
      if (!ref.fileName.startsWith('.')) continue;
      const base = path.posix.normalize(path.posix.join(path.posix.dirname(file), ref.fileName));
      const target = [base, `${base}.ts`, `${base}/index.ts`].find((c) => sources.has(c));
      if (target && !deps.includes(target)) deps.push(target);
    }
    graph.set(file, deps);
  }
  return graph;
}

/**
 * Every import loop, each as the files around it from its first file in sort order (repeated at
 * the end).
 */
function importCycles(sources: ReadonlyMap<string, string>): string[][] {
  const graph = importGraph(sources);
  const cycles: string[][] = [];
  const state = new Map<string, 'open' | 'done'>();
  const stack: string[] = [];
  const visit = (f: string): void => {
    state.set(f, 'open');
    stack.push(f);
    for (const d of graph.get(f) ?? []) {
      if (state.get(d) === 'open') {
        const ring = stack.slice(stack.indexOf(d));
        const first = ring.indexOf([...ring].sort()[0] ?? d);
        const from = [...ring.slice(first), ...ring.slice(0, first)];
        cycles.push([...from, from[0] ?? d]);
      } else if (!state.has(d)) visit(d);
    }
    stack.pop();
    state.set(f, 'done');
  };
  for (const f of [...graph.keys()].sort()) if (!state.has(f)) visit(f);
  return cycles;
}

/** The loops this test refuses: through a module of gateway/ itself or of gateway/routes/. */
function gatewayCycles(sources: ReadonlyMap<string, string>): string[] {
  const core = (f: string): boolean => /^(routes\/)?[^/]+\.ts$/.test(f);
  return importCycles(sources)
    .filter((c) => c.some(core))
    .map((c) => c.join(' → '));
}

describe('the gateway modules import one another without a loop', () => {
  it('finds no cycle through gateway/*.ts or gateway/routes/*.ts', () => {
    const sources = gatewaySources();
    // The walk sees the modules it is about (a rename would otherwise make this pass vacuously).
    for (const f of ['context.ts', 'held-session.ts', 'upstream-http.ts', 'routes/route.ts'])
      expect(sources.has(f), f).toBe(true);
    expect(importGraph(sources).get('context.ts')).toContain('upstream-http.ts');
    expect(gatewayCycles(sources)).toEqual([]);
  });

  it('fails on a constructed loop, type-only imports and re-exports included', () => {
    const sources = gatewaySources();
    // held-session imports context's type again, as it did before issue 34: the old loop.
    const looped = new Map(sources);
    looped.set(
      'held-session.ts',
      `import type { GatewayContext } from './context';\n${sources.get('held-session.ts') ?? ''}`,
    );
    looped.set(
      'context.ts',
      `import type { HeldSession } from './held-session';\n${sources.get('context.ts') ?? ''}`,
    );
    expect(gatewayCycles(looped)).toContain('context.ts → held-session.ts → context.ts');
    // A route module and a module it is given by, through a re-export.
    const reexport = new Map(sources);
    reexport.set(
      'http-util.ts',
      `export type { ApiRoute } from './routes/route';\n${sources.get('http-util.ts') ?? ''}`,
    );
    expect(gatewayCycles(reexport)).toContain('http-util.ts → routes/route.ts → http-util.ts');
    // Three files in a ring, apart from the real ones.
    const ring = new Map([
      ['a.ts', "import { b } from './b';"],
      ['b.ts', "import type { C } from './routes/c';"],
      ['routes/c.ts', "export * from '../a';"],
    ]);
    expect(gatewayCycles(ring)).toEqual(['a.ts → b.ts → routes/c.ts → a.ts']);
    // Found wherever the walk starts: the same ring entered from its last file.
    const entered = new Map([...ring].reverse());
    expect(gatewayCycles(entered)).toEqual(['a.ts → b.ts → routes/c.ts → a.ts']);
    // A loop outside gateway/ itself and routes/ is not this test's (history/ has its own).
    expect(
      gatewayCycles(
        new Map([
          ['x/a.ts', "import './b';"],
          ['x/b.ts', "import './a';"],
        ]),
      ),
    ).toEqual([]);
  });
});
