/**
 * Heap snapshots for the browser benches: take one over CDP (HeapProfiler.takeHeapSnapshot, its
 * chunks streamed to a file) and compare two (parsed here from the .heapsnapshot JSON: nodes,
 * edges, strings and the meta fields). The comparison lists, per constructor (objects by class
 * name, closures by function name, strings together, internal arrays by their kind), the count
 * and self size in each snapshot and the difference, largest growth first; for the top growers,
 * the retainer paths of their objects that are new in the second snapshot (node ids are stable
 * within one page), so a list that keeps growing shows who holds it.
 *
 *     npx tsx tests/bench/heap-snapshot.ts a.heapsnapshot b.heapsnapshot [top=40] [retained=3]
 *
 * fleet100.bench.ts uses it with BENCH_FLEET_SNAPSHOTS=<dir> (see its header).
 */
import { createWriteStream, readFileSync } from 'node:fs';
import { pathToFileURL } from 'node:url';
import { type CDPSession } from '@playwright/test';

/** Takes a heap snapshot of the page (after a forced GC) into `file`. */
export async function takeSnapshot(cdp: CDPSession, file: string): Promise<void> {
  const out = createWriteStream(file);
  const onChunk = ({ chunk }: { chunk: string }): void => {
    out.write(chunk);
  };
  cdp.on('HeapProfiler.addHeapSnapshotChunk', onChunk);
  try {
    await cdp.send('HeapProfiler.enable');
    await cdp.send('HeapProfiler.collectGarbage');
    await cdp.send('HeapProfiler.takeHeapSnapshot', { reportProgress: false });
  } finally {
    cdp.off('HeapProfiler.addHeapSnapshotChunk', onChunk);
    await new Promise<void>((resolve, reject) => out.end((e?: Error | null) => (e ? reject(e) : resolve())));
  }
}

interface RawSnapshot {
  snapshot: {
    meta: {
      node_fields: string[];
      node_types: [string[], ...unknown[]];
      edge_fields: string[];
      edge_types: [string[], ...unknown[]];
    };
  };
  nodes: number[];
  edges: number[];
  strings: string[];
}

/** One snapshot, flattened: per node its group key, id, self size and its retainers. */
export interface Heap {
  count: number;
  key: string[];
  id: Float64Array;
  size: Float64Array;
  /** Retaining edges per node (node index, edge label), weak edges left out. */
  retainers: Array<Array<[number, string]>>;
}

const STRING_TYPES = new Set(['string', 'concatenated string', 'sliced string']);

export function parseSnapshot(text: string): Heap {
  const raw = JSON.parse(text) as RawSnapshot;
  const { meta } = raw.snapshot;
  const nf = meta.node_fields.length;
  const ef = meta.edge_fields.length;
  const fType = meta.node_fields.indexOf('type');
  const fName = meta.node_fields.indexOf('name');
  const fId = meta.node_fields.indexOf('id');
  const fSize = meta.node_fields.indexOf('self_size');
  const fEdges = meta.node_fields.indexOf('edge_count');
  const eType = meta.edge_fields.indexOf('type');
  const eName = meta.edge_fields.indexOf('name_or_index');
  const eTo = meta.edge_fields.indexOf('to_node');
  const nodeTypes = meta.node_types[0];
  const edgeTypes = meta.edge_types[0];
  const count = raw.nodes.length / nf;
  const key: string[] = new Array<string>(count);
  const id = new Float64Array(count);
  const size = new Float64Array(count);
  const retainers: Array<Array<[number, string]>> = Array.from({ length: count }, () => []);
  let e = 0;
  for (let i = 0; i < count; i++) {
    const o = i * nf;
    const type = nodeTypes[raw.nodes[o + fType] as number] ?? '?';
    const name = raw.strings[raw.nodes[o + fName] as number] ?? '';
    key[i] = STRING_TYPES.has(type)
      ? '(string)'
      : type === 'object' || type === 'native'
        ? name
        : type === 'closure'
          ? `(closure) ${name}`
          : type === 'array' || type === 'hidden' || type === 'object shape'
            ? `(${type}) ${name}`
            : `(${type})`;
    id[i] = raw.nodes[o + fId] as number;
    size[i] = raw.nodes[o + fSize] as number;
    const edges = raw.nodes[o + fEdges] as number;
    for (let k = 0; k < edges; k++, e++) {
      const eo = e * ef;
      const et = edgeTypes[raw.edges[eo + eType] as number] ?? '?';
      if (et === 'weak' || et === 'shortcut') continue;
      const n = raw.edges[eo + eName] as number;
      const label = et === 'element' || et === 'hidden' ? `[${n}]` : (raw.strings[n] ?? String(n));
      retainers[(raw.edges[eo + eTo] as number) / nf]?.push([i, label]);
    }
  }
  return { count, key, id, size, retainers };
}

export interface Row {
  name: string;
  countA: number;
  countB: number;
  sizeA: number;
  sizeB: number;
  dCount: number;
  dSize: number;
}

/** Per group: count and self size in each snapshot and the difference, largest growth first. */
export function compare(a: Heap, b: Heap): Row[] {
  const rows = new Map<string, Row>();
  const add = (h: Heap, which: 'A' | 'B'): void => {
    for (let i = 0; i < h.count; i++) {
      const name = h.key[i] as string;
      let r = rows.get(name);
      if (!r) {
        r = { name, countA: 0, countB: 0, sizeA: 0, sizeB: 0, dCount: 0, dSize: 0 };
        rows.set(name, r);
      }
      if (which === 'A') {
        r.countA++;
        r.sizeA += h.size[i] as number;
      } else {
        r.countB++;
        r.sizeB += h.size[i] as number;
      }
    }
  };
  add(a, 'A');
  add(b, 'B');
  return [...rows.values()]
    .map((r) => ({ ...r, dCount: r.countB - r.countA, dSize: r.sizeB - r.sizeA }))
    .sort((x, y) => y.dSize - x.dSize || y.dCount - x.dCount);
}

/** The most common retainer paths (up to `depth` steps) of `name`'s objects new in `b`. */
export function newRetainerPaths(
  a: Heap,
  b: Heap,
  name: string,
  depth = 8,
  sample = 300,
): Array<[string, number]> {
  const old = new Set<number>();
  for (let i = 0; i < a.count; i++) if (a.key[i] === name) old.add(a.id[i] as number);
  const paths = new Map<string, number>();
  let seen = 0;
  for (let i = 0; i < b.count && seen < sample; i++) {
    if (b.key[i] !== name || old.has(b.id[i] as number)) continue;
    seen++;
    const steps: string[] = [];
    const visited = new Set<number>([i]);
    let at = i;
    for (let d = 0; d < depth; d++) {
      // The first retainer not yet on the path (a cycle would loop forever).
      const next = (b.retainers[at] ?? []).find(([from]) => !visited.has(from));
      if (!next) break;
      steps.push(`${next[1]} ← ${b.key[next[0]]}`);
      visited.add(next[0]);
      at = next[0];
    }
    const p = steps.join(' ← ');
    paths.set(p, (paths.get(p) ?? 0) + 1);
  }
  return [...paths.entries()].sort((x, y) => y[1] - x[1]).slice(0, 5);
}

const kib = (n: number): string => (n / 1024).toFixed(1);

/** The comparison as text: the table of the top `top` growers, the retainer paths of the first `retained`. */
export function comparisonText(a: Heap, b: Heap, top = 40, retained = 3): string {
  const rows = compare(a, b);
  const total = (h: Heap): number => h.size.reduce((s, x) => s + x, 0);
  const lines = [
    `total self size: ${kib(total(a))} KiB → ${kib(total(b))} KiB (${kib(total(b) - total(a))} KiB), nodes ${a.count} → ${b.count}`,
    '',
    'Δ self KiB | Δ count | count A → B | self KiB A → B | constructor',
    ...rows
      .slice(0, top)
      .map(
        (r) =>
          `${kib(r.dSize).padStart(10)} | ${String(r.dCount).padStart(7)} | ${r.countA} → ${r.countB} | ${kib(r.sizeA)} → ${kib(r.sizeB)} | ${r.name}`,
      ),
  ];
  for (const r of rows.slice(0, retained)) {
    if (r.dCount <= 0) continue;
    lines.push('', `retainers of new ${r.name} (most common paths, up to 8 steps):`);
    for (const [p, n] of newRetainerPaths(a, b, r.name)) lines.push(`  ${n}×  ${p}`);
  }
  return `${lines.join('\n')}\n`;
}

if (import.meta.url === pathToFileURL(process.argv[1] ?? '').href) {
  const [fa, fb, top, retained] = process.argv.slice(2);
  if (!fa || !fb) throw new Error('usage: heap-snapshot.ts a.heapsnapshot b.heapsnapshot [top] [retained]');
  const a = parseSnapshot(readFileSync(fa, 'utf8'));
  const b = parseSnapshot(readFileSync(fb, 'utf8'));
  process.stdout.write(comparisonText(a, b, Number(top ?? 40), Number(retained ?? 3)));
}
