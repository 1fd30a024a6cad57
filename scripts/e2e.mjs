#!/usr/bin/env node
// The browser tests, in SHOPDECK_E2E_LANES lanes side by side (2 unless said). The (project, spec
// file) pairs, tablet and desktop, are dealt to the lanes by their measured seconds
// (tests/e2e/weights.json, from a CI run's log; a file not in it counts as 20 s), longest first,
// each to the least loaded lane; a lane runs one Playwright process per project it holds, one after
// the other, each with its own production server (its own port, data folder and simulated fleet)
// and results folder, so none sees another's machines. Two lanes because one lane of browser tests
// keeps two cores about two-thirds busy and two nearly all (docs/performance.md, "the test run"):
// a third adds load, not speed. Arguments (a spec file, --grep) run one process per project, the
// two side by side; with --project=<name> only that one runs.
// SHOPDECK_E2E_SERIAL=1 runs everything one process after another.
// At the end each process's failed and flaky tests are said again, together, so a log that keeps
// only its last lines still names them (CI keeps the tail).
import { spawn } from 'node:child_process';
import { readdirSync, readFileSync } from 'node:fs';
import { StringDecoder } from 'node:string_decoder';

const args = process.argv.slice(2);
const chosen = args.some((a) => a.startsWith('--project'));
const base = Number(process.env.SHOPDECK_E2E_PORT ?? 4180);
const PROJECTS = ['tablet', 'desktop'];

/** A Playwright process: its name and arguments. */
/** @typedef {{ name: string, extra: string[] }} Run */

/** The lanes: each a list of runs, one after another. */
function lanes(n) {
  const weights = JSON.parse(readFileSync('tests/e2e/weights.json', 'utf8'));
  const files = readdirSync('tests/e2e').filter((f) => f.endsWith('.spec.ts'));
  // Not measured in a project but in the other: its tests there are all skipped.
  const known = (f) => PROJECTS.some((p) => weights[p]?.[f] !== undefined);
  const items = PROJECTS.flatMap((project) =>
    files.map((f) => ({ project, f, w: weights[project]?.[f] ?? (known(f) ? 0 : 20) })),
  ).sort((a, b) => b.w - a.w || a.f.localeCompare(b.f) || a.project.localeCompare(b.project));
  const bins = Array.from({ length: n }, () => ({ w: 0, items: [] }));
  for (const item of items) {
    const bin = bins.reduce((least, b) => (b.w < least.w ? b : least));
    bin.w += item.w;
    bin.items.push(item);
  }
  return bins.map((bin, k) =>
    PROJECTS.map((project) => ({
      name: `${project} (lane ${k + 1})`,
      extra: [
        `--project=${project}`,
        `--output=test-results/${project}-${k + 1}`,
        // A regular expression each (Playwright's filter): the file's name exactly.
        ...bin.items
          .filter((i) => i.project === project)
          .map((i) => `tests/e2e/${i.f.replaceAll('.', '\\.')}$`),
      ],
    })).filter((r) => r.extra.length > 2),
  );
}

/** @type {Run[][]} */
const plan = chosen
  ? [[{ name: 'chosen', extra: [] }]]
  : args.length
    ? PROJECTS.map((p) => [{ name: p, extra: [`--project=${p}`, `--output=test-results/${p}`] }])
    : lanes(Math.max(1, Number(process.env.SHOPDECK_E2E_LANES) || 2));

if (process.env.SHOPDECK_E2E_PLAN === '1') {
  for (const [k, list] of plan.entries()) console.log(`lane ${k + 1}:`, JSON.stringify(list, null, 1));
  process.exit(0);
}

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
const runs = plan.flat();
/** @type {number[]} */
const codes = new Array(runs.length).fill(0);
const index = (r) => runs.indexOf(r);
async function lane(list) {
  for (const r of list) codes[index(r)] = await run(r, index(r));
}
if (serial) for (const list of plan) await lane(list);
else await Promise.all(plan.map(lane));
const failed = codes.some((c) => c !== 0);
for (const [name, lines] of said)
  if (lines.length) console.log(`\n── ${name}: failed or flaky\n${lines.join('\n')}`);
if (runs.length > 1)
  console.log(
    `browser tests: ${runs.map((r, i) => `${r.name} ${codes[i] === 0 ? 'passed' : 'FAILED'}`).join(', ')}`,
  );
process.exit(failed ? 1 : 0);
