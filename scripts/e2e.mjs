#!/usr/bin/env node
// The browser tests: the tablet and the desktop projects run side by side, each in its own
// Playwright process with its own production server (its own port, data folder and simulated
// fleet) and its own results folder, so neither sees the other's machines. Most of a browser test
// is waiting on the machines and the page, so the two share a 2-core machine well (measured:
// docs/performance.md, "the test run"). Arguments go to both (a spec file, --grep); with
// --project=<name> only that one runs. SHOPDECK_E2E_SERIAL=1 runs the projects one after another.
import { spawn } from 'node:child_process';

const args = process.argv.slice(2);
const chosen = args.filter((a) => a.startsWith('--project')).length > 0;
const base = Number(process.env.SHOPDECK_E2E_PORT ?? 4180);
const projects = chosen ? [null] : ['tablet', 'desktop'];

function run(project, i) {
  return new Promise((resolve) => {
    const extra = project ? [`--project=${project}`, `--output=test-results/${project}`] : [];
    const child = spawn(
      process.execPath,
      ['node_modules/@playwright/test/cli.js', 'test', ...extra, ...args],
      {
        stdio: 'inherit',
        env: {
          ...process.env,
          SHOPDECK_E2E_PORT: String(base + i),
          // Each process makes its own data folder (playwright.config.ts) unless one is given.
          SHOPDECK_E2E_DATA: process.env.SHOPDECK_E2E_DATA ? `${process.env.SHOPDECK_E2E_DATA}-${i}` : '',
        },
      },
    );
    child.on('exit', (code, signal) => resolve(code ?? (signal ? 1 : 0)));
  });
}

const serial = process.env.SHOPDECK_E2E_SERIAL === '1';
const codes = [];
if (serial) for (const [i, p] of projects.entries()) codes.push(await run(p, i));
else codes.push(...(await Promise.all(projects.map((p, i) => run(p, i)))));
const failed = codes.some((c) => c !== 0);
if (projects.length > 1)
  console.log(
    `browser tests: ${projects.map((p, i) => `${p} ${codes[i] === 0 ? 'passed' : 'FAILED'}`).join(', ')}`,
  );
process.exit(failed ? 1 : 0);
