#!/usr/bin/env node
// Writes tests/e2e/weights.json (the seconds of each spec file in each project, which
// scripts/e2e.mjs uses to deal the files to its lanes) from the log of a browser-test run:
//   npm run test:e2e 2>&1 | tee /tmp/e2e.log; node scripts/e2e-weights.mjs /tmp/e2e.log
// Each passed, failed or flaky test's line ("✓  12 [tablet] › tests/e2e/x.spec.ts:3:5 › … (4.2s)")
// adds its time to its file in its project.
import { readFileSync, writeFileSync } from 'node:fs';

const file = process.argv[2];
if (!file) {
  console.error('usage: node scripts/e2e-weights.mjs <log of a browser-test run>');
  process.exit(2);
}
const LINE = /\[(\w+)\] › (?:tests\/e2e\/)?([\w.-]+\.spec\.ts):.*\((\d+(?:\.\d+)?)(ms|s|m)\)\s*$/;
/** @type {Record<string, Record<string, number>>} */
const seconds = {};
for (const raw of readFileSync(file, 'utf8').split('\n')) {
  const line = raw.replace(/\x1b\[[0-9;]*m/g, ''); // eslint-disable-line no-control-regex
  const m = LINE.exec(line);
  if (!m) continue;
  const [, project, spec, value, unit] = m;
  const s = Number(value) * (unit === 'ms' ? 0.001 : unit === 'm' ? 60 : 1);
  seconds[project] ??= {};
  seconds[project][spec] = (seconds[project][spec] ?? 0) + s;
}
if (Object.keys(seconds).length === 0) {
  console.error(`${file}: no test lines found`);
  process.exit(1);
}
const rounded = Object.fromEntries(
  Object.entries(seconds).map(([p, files]) => [
    p,
    Object.fromEntries(
      Object.entries(files)
        .sort(([a], [b]) => a.localeCompare(b))
        .map(([f, s]) => [f, Math.round(s)]),
    ),
  ]),
);
writeFileSync('tests/e2e/weights.json', `${JSON.stringify(rounded, null, 2)}\n`);
for (const [p, files] of Object.entries(rounded))
  console.log(
    `${p}: ${Object.keys(files).length} files, ${Object.values(files).reduce((a, b) => a + b, 0)} s`,
  );
