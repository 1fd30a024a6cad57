/**
 * First-screen sizes (issue 16), from the report the build writes (bundle-report/bundle.json):
 * gzip JS+CSS of each screen beside the targets — the fleet page's first screen ≤ 150 KiB,
 * a kiosk machine page ≤ 120 KiB. Sizes, not timings: the same on any machine for the same build.
 * The ceilings `npm test` enforces are in tests/bundle/budgets.ts.
 *
 *     npm run bench -- bundle
 */
import { readFileSync } from 'node:fs';
import path from 'node:path';
import type { BundleReport } from '../../scripts/bundle-report';
import { ensureDist, root } from './harness';
import { report, round } from './util';

const TARGETS: Array<{ screen: RegExp; kib: number }> = [
  // The live tiles' family code loads after the first screen, at idle: reported, no target.
  { screen: /^fleet page: first screen/, kib: 150 },
  // The second target is a kiosk tablet's page (`/m/<id>?kiosk`): its first screen, the
  // machine from the server's reading; its family's code (its controls) loads right after.
  { screen: /^kiosk page: first screen/, kib: 120 },
];

ensureDist();
const r = JSON.parse(readFileSync(path.join(root, 'bundle-report', 'bundle.json'), 'utf8')) as BundleReport;
for (const s of r.screens) {
  const target = TARGETS.find((t) => t.screen.test(s.name))?.kib;
  const kib = s.gzip / 1024;
  report({
    name: s.name,
    gzip_kib: round(kib, 1),
    raw_kib: round(s.bytes / 1024, 1),
    files: s.files.length,
    ...(target !== undefined
      ? { target_kib: target, meets: kib <= target ? 'yes' : `no: ${round(kib - target, 1)} KiB over` }
      : {}),
  });
}
