#!/usr/bin/env node
// The browser tests: each project (tablet, desktop) in SHOPDECK_E2E_SHARDS Playwright processes
// (2 unless said), all side by side, each with its own production server (its own port, data
// folder and simulated fleet) and results folder, so none sees another's machines. The spec files
// are dealt to a project's processes by their measured seconds (tests/e2e/weights.json, from a CI
// run's log; a file not in it counts as 20 s), longest first, each to the least loaded process.
// Much of a browser test is waiting on the machines and the page, so more processes than cores
// fill the gaps (measured: docs/performance.md, "the test run"). Arguments (a spec file, --grep)
// go to one process per project; with --project=<name> only that one runs.
// SHOPDECK_E2E_SERIAL=1 runs the processes one after another.
// At the end each process's failed and flaky tests are said again, together, so a log that keeps
// only its last lines still names them (CI keeps the tail).
import { spawn } from 'node:child_process';
import { readdirSync, readFileSync } from 'node:fs';
import { StringDecoder } from 'node:string_decoder';

const args = process.argv.slice(2);
const chosen = args.filter((a) => a.startsWith('--project')).length > 0;
const base = Number(process.env.SHOPDECK_E2E_PORT ?? 4180);
const shards = args.length ? 1 : Math.max(1, Number(process.env.SHOPDECK_E2E_SHARDS) || 2);

/** The spec files dealt to `n` processes by their weights for `project`, heaviest first. */
function deal(project, n) {
  const weights = JSON.parse(readFileSync('tests/e2e/weights.json', 'utf8'))[project] ?? {};
  const files = readdirSync('tests/e2e')
    .filter((f) => f.endsWith('.spec.ts'))
    .map((f) => ({ f, w: weights[f] ?? 20 }))
    .sort((a, b) => b.w - a.w || a.f.localeCompare(b.f));
  const bins = Array.from({ length: n }, () => ({ w: 0, files: [] }));
  for (const { f, w } of files) {
    const bin = bins.reduce((least, b) => (b.w < least.w ? b : least));
    bin.w += w;
    bin.files.push(`tests/e2e/${f.replaceAll(".", "\\.")}$`);
  }
  return bins.map((b) => b.files);
}

/** Each process: its name, its Playwright arguments. */
const runs = chosen
  ? [{ name: 'chosen', extra: [] }]
  : ['tablet', 'desktop'].flatMap((project) =>
      shards === 1
        ? [{ name: project, extra: [`--project=${project}`, `--output=test-results/${project}`] }]
        : deal(project, shards).map((files, k) => ({
            name: `${project} ${k + 1}/${shards}`,
            extra: [`--project=${project}`, `--output=test-results/${project}-${k + 1}`, ...files],
          })),
    );

/** Per project: the lines of Playwright's closing summary (failed, flaky) and every ✘ line. */
const said = new Map();

function run({ name, extra }, i) {
  const lines = [];
  said.set(name, lines);
  return new Promise((resolve) => {
    const child = spawn(
      process.execPath,
      ['node_modules/@playwright/test/cli.js', 'test', ...extra, ...args],
      {
        stdio: ['inherit', 'pipe', 'inherit'],
        env: {
          ...process.env,
          SHOPDECK_E2E_PORT: String(base + i),
          // Each process makes its own data folder (playwright.config.ts) unless one is given.
          SHOPDECK_E2E_DATA: process.env.SHOPDECK_E2E_DATA ? `${process.env.SHOPDECK_E2E_DATA}-${i}` : '',
        },
      },
    );
    let rest = '';
    let inSummary = false;
    const text = new StringDecoder('utf8');
    child.stdout.on('data', (chunk) => {
      process.stdout.write(chunk);
      const parts = (rest + text.write(chunk)).split('\n');
      rest = parts.pop() ?? '';
      for (const line of parts) {
        // The closing summary: "  2 failed" / "  1 flaky", then the tests it names, indented.
        if (/^\s+\d+ (failed|flaky)$/.test(line)) inSummary = true;
        else if (/^\s+\d+ (skipped|passed|did not run)/.test(line)) inSummary = false;
        if (line.includes('✘') || inSummary) lines.push(line);
      }
    });
    // 'close', not 'exit': the last of its output is read by then.
    child.on('close', (code, signal) => {
      const c = code ?? (signal ? 1 : 0);
      if (c !== 0 && lines.length === 0)
        lines.push(`  exited with ${code ?? signal} and named no failed test`);
      resolve(c);
    });
  });
}

const serial = process.env.SHOPDECK_E2E_SERIAL === '1';
const codes = [];
if (serial) for (const [i, r] of runs.entries()) codes.push(await run(r, i));
else codes.push(...(await Promise.all(runs.map((r, i) => run(r, i)))));
const failed = codes.some((c) => c !== 0);
for (const [name, lines] of said)
  if (lines.length) console.log(`\n── ${name}: failed or flaky\n${lines.join('\n')}`);
if (runs.length > 1)
  console.log(
    `browser tests: ${runs.map((r, i) => `${r.name} ${codes[i] === 0 ? 'passed' : 'FAILED'}`).join(', ')}`,
  );
process.exit(failed ? 1 : 0);
