import { existsSync, readFileSync } from 'node:fs';
import path from 'node:path';
import { describe, expect, it } from 'vitest';
import type { BundleReport } from '../../scripts/bundle-report';
import { MACHINE_KINDS } from '../../src/controllers';
import { overBudget, SIZE_BUDGETS_KIB } from './budgets';

/**
 * The size check of issue 16: the JS+CSS (gzip) each screen of the built console loads, from the
 * report `npm run build` writes (bundle-report/bundle.json), against its ceiling. A size, not a
 * timing: stable on any machine. Run after the build (`npm run test:bundle`, part of `npm test`).
 */
const file = path.resolve(import.meta.dirname, '..', '..', 'bundle-report', 'bundle.json');

describe('bundle budget', () => {
  it('has a bundle report from the build', () => {
    expect(existsSync(file), `${file} is missing: run \`npm run build\` first`).toBe(true);
  });

  const report = existsSync(file) ? (JSON.parse(readFileSync(file, 'utf8')) as BundleReport) : null;

  it('reports every screen: the shell, each family, each machine page, the fleet page', () => {
    const names = report?.screens.map((s) => s.name) ?? [];
    expect(names).toContain('shell');
    expect(names).toContain('fleet page: first screen');
    expect(names).toContain('kiosk page: first screen');
    expect(names).toContain('fleet page, live tiles: all five families');
    for (const kind of MACHINE_KINDS) {
      expect(names).toContain(`family: ${kind}`);
      expect(names).toContain(`machine page: ${kind}`);
      expect(names).toContain(`kiosk page, live: ${kind}`);
    }
  });

  it('keeps every screen within its budget', () => {
    const over = overBudget(report?.screens ?? [], SIZE_BUDGETS_KIB);
    expect(over, over.join('\n')).toEqual([]);
  });
});
