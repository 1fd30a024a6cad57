#!/usr/bin/env node
// The browser tests: the tablet and the desktop projects run side by side, each in its own
// Playwright process with its own production server (its own port, data folder and simulated
// fleet) and its own results folder, so neither sees the other's machines. Most of a browser test
// is waiting on the machines and the page, so the two share a 2-core machine well (measured:
// docs/performance.md, "the test run"). Arguments go to both (a spec file, --grep); with
// --project=<name> only that one runs. SHOPDECK_E2E_SERIAL=1 runs the projects one after another.
// At the end each project's failed and flaky tests are said again, together, so a log that keeps
// only its last lines still names them (CI keeps the tail).
import { spawn } from 'node:child_process';
import { StringDecoder } from 'node:string_decoder';

const args = process.argv.slice(2);
const chosen = args.filter((a) => a.startsWith('--project')).length > 0;
const base = Number(process.env.SHOPDECK_E2E_PORT ?? 4180);
const projects = chosen ? [null] : ['tablet', 'desktop'];

/** Per project: the lines of Playwright's closing summary (failed, flaky) and every ✘ line. */
const said = new Map();

function run(project, i) {
  const lines = [];
  said.set(project ?? 'chosen', lines);
  return new Promise((resolve) => {
    const extra = project ? [`--project=${project}`, `--output=test-results/${project}`] : [];
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
if (serial) for (const [i, p] of projects.entries()) codes.push(await run(p, i));
else codes.push(...(await Promise.all(projects.map((p, i) => run(p, i)))));
const failed = codes.some((c) => c !== 0);
for (const [name, lines] of said)
  if (lines.length) console.log(`\n── ${name}: failed or flaky\n${lines.join('\n')}`);
if (projects.length > 1)
  console.log(
    `browser tests: ${projects.map((p, i) => `${p} ${codes[i] === 0 ? 'passed' : 'FAILED'}`).join(', ')}`,
  );
process.exit(failed ? 1 : 0);
