/**
 * `npm run bench`: runs every `tests/bench/*.bench.ts` in its own process (so one benchmark's
 * garbage does not tax the next), collects the JSON lines each prints, and writes
 * `bench-report/report.json` and `bench-report/report.md`. Numbers are medians of one run on
 * this machine; compare ratios inside one report, not absolute times across machines.
 */
import { execFileSync } from 'node:child_process';
import { mkdirSync, readdirSync, writeFileSync } from 'node:fs';
import { cpus, totalmem } from 'node:os';
import { join } from 'node:path';

interface Row {
  bench: string;
  name: string;
  [k: string]: unknown;
}

const dir = new URL('.', import.meta.url).pathname;
const only = process.argv[2];
const files = readdirSync(dir)
  .filter((f) => f.endsWith('.bench.ts'))
  .filter((f) => !only || f.includes(only))
  .sort();
const rows: Row[] = [];
for (const f of files) {
  process.stdout.write(`running ${f}…\n`);
  let out = '';
  try {
    out = execFileSync(process.execPath, ['--expose-gc', '--import', 'tsx', join(dir, f)], {
      encoding: 'utf8',
      maxBuffer: 64 * 1024 * 1024,
      stdio: ['ignore', 'pipe', 'inherit'],
    });
  } catch (e) {
    rows.push({ bench: f, name: 'FAILED', error: e instanceof Error ? e.message : String(e) });
    continue;
  }
  for (const line of out.split('\n')) {
    const t = line.trim();
    if (!t.startsWith('{')) continue;
    try {
      rows.push({ bench: f, ...(JSON.parse(t) as { name: string }) });
    } catch {
      /* not a result line */
    }
  }
}
const outDir = join(process.cwd(), 'bench-report');
mkdirSync(outDir, { recursive: true });
const meta = {
  date: new Date().toISOString(),
  node: process.version,
  cpus: cpus().length,
  cpu: cpus()[0]?.model ?? 'unknown',
  memGiB: Math.round(totalmem() / 2 ** 30),
};
writeFileSync(join(outDir, 'report.json'), JSON.stringify({ meta, rows }, null, 2));
/** A table cell: nothing for a missing value, "—" for null, no line breaks or pipes. */
const cell = (v: unknown): string =>
  v === undefined
    ? ''
    : v === null
      ? '—'
      : String(v)
          .replace(/\s*\n\s*/g, ' ')
          .replace(/\|/g, '\\|');
// One table per benchmark, with that benchmark's own columns (in the order its rows give them).
const tables = [...new Set(rows.map((r) => r.bench))].flatMap((bench) => {
  const own = rows.filter((r) => r.bench === bench);
  const keys = [...new Set(own.flatMap((r) => Object.keys(r)))].filter((k) => k !== 'bench');
  return [
    `## ${bench}`,
    '',
    `| ${keys.join(' | ')} |`,
    `|${keys.map(() => '---').join('|')}|`,
    ...own.map((r) => `| ${keys.map((k) => cell(r[k])).join(' | ')} |`),
    '',
  ];
});
const md = [
  `# Shopdeck benchmark report`,
  '',
  `${meta.date} · Node ${meta.node} · ${meta.cpus} × ${meta.cpu} · ${meta.memGiB} GiB`,
  '',
  'Medians of one run on a shared, noisy machine: read ratios within this report.',
  '',
  ...tables,
].join('\n');
writeFileSync(join(outDir, 'report.md'), md);
process.stdout.write(md);
const failed = rows.filter((r) => r.name === 'FAILED');
if (failed.length) process.exit(1);
