#!/usr/bin/env node
// `npm test`: every check, in three phases, with a summary of each step's time at the end.
//
//  1. lint and format, the type check and the production build, side by side: each is mostly one
//     process on one core (ESLint, tsc, the bundler's JS), so on two cores the three take about
//     as long as the longest instead of their sum (measured: docs/performance.md, "the test run").
//     Their output is held and printed whole, one after another, when each ends.
//  2. vitest: unit and integration in one run (two workers), the fault matrix, then the bundle and
//     packaging checks (they read dist/ from phase 1).
//  3. the browser tests (scripts/e2e.mjs).
//
// Every step runs even when an earlier one failed (one CI run says everything that is wrong),
// except that phases 2 and 3 need the build. Exit code 1 when any step failed.
// SHOPDECK_TEST_ONLY=lint,typecheck,… runs only the named steps (for trying the runner itself).
import { spawn } from 'node:child_process';
import { StringDecoder } from 'node:string_decoder';

const only = new Set((process.env.SHOPDECK_TEST_ONLY ?? '').split(',').filter(Boolean));
const npx = (bin, ...args) => [process.execPath, [`node_modules/${bin}`, ...args]];

/** @type {Record<string, Array<[string, string[]]>>} each step: its commands, one after another. */
const STEPS = {
  lint: [npx('eslint/bin/eslint.js', '.'), npx('prettier/bin/prettier.cjs', '--check', '.')],
  typecheck: [npx('typescript/bin/tsc', '-p', 'tsconfig.json', '--noEmit')],
  build: [['npm', ['run', '--silent', 'build']]],
  'unit+integration': [npx('vitest/vitest.mjs', 'run', '--project', 'unit', '--project', 'integration')],
  faults: [npx('vitest/vitest.mjs', 'run', '--project', 'faults')],
  bundle: [npx('vitest/vitest.mjs', 'run', '--project', 'bundle')],
  e2e: [
    [process.execPath, ['scripts/check-browser.mjs']],
    [process.execPath, ['scripts/e2e.mjs']],
  ],
};

/** @type {Array<{ step: string, ok: boolean, seconds: number }>} */
const done = [];

/** Runs one step's commands in order; `hold` keeps the output until the end (printed whole). */
function runStep(step, hold) {
  const started = Date.now();
  const out = [];
  const write = (chunk) => (hold ? out.push(chunk) : process.stdout.write(chunk));
  if (!hold) console.log(`\n━━ ${step}`);
  return STEPS[step]
    .reduce(
      (prev, [cmd, args]) =>
        prev.then(
          (ok) =>
            ok &&
            new Promise((resolve) => {
              const child = spawn(cmd, args, { stdio: ['ignore', 'pipe', 'pipe'], env: process.env });
              const dec = [new StringDecoder('utf8'), new StringDecoder('utf8')];
              child.stdout.on('data', (c) => write(dec[0].write(c)));
              child.stderr.on('data', (c) => write(dec[1].write(c)));
              child.on('error', (e) => {
                write(`${step}: could not start ${cmd}: ${e.message}\n`);
                resolve(false);
              });
              child.on('close', (code) => resolve(code === 0));
            }),
        ),
      Promise.resolve(true),
    )
    .then((ok) => {
      const seconds = (Date.now() - started) / 1000;
      if (hold)
        console.log(`\n━━ ${step} (${ok ? 'passed' : 'FAILED'}, ${seconds.toFixed(0)} s)\n${out.join('')}`);
      done.push({ step, ok, seconds });
      return ok;
    });
}

const wanted = (step) => only.size === 0 || only.has(step);
const t0 = Date.now();

// Phase 1: side by side.
const first = ['lint', 'typecheck', 'build'].filter(wanted);
const results = await Promise.all(first.map((s) => runStep(s, true)));
const built = !first.includes('build') || results[first.indexOf('build')];

// Phases 2 and 3: one after another.
for (const step of ['unit+integration', 'faults', 'bundle', 'e2e'].filter(wanted)) {
  if ((step === 'bundle' || step === 'e2e') && !built) {
    done.push({ step, ok: false, seconds: 0 });
    console.log(`\n━━ ${step}: not run (the build failed)`);
    continue;
  }
  await runStep(step, false);
}

const minutes = (s) => `${(s / 60).toFixed(1)} min`;
console.log('\n━━ npm test');
for (const { step, ok, seconds } of done)
  console.log(`  ${ok ? 'passed' : 'FAILED'}  ${step.padEnd(18)} ${minutes(seconds)}`);
const failed = done.filter((d) => !d.ok);
console.log(
  `  ${failed.length ? `${failed.length} FAILED` : 'all passed'} in ${minutes((Date.now() - t0) / 1000)}`,
);
process.exit(failed.length ? 1 : 0);
