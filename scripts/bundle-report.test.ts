import { describe, expect, it } from 'vitest';
import { overBudget } from '../tests/bundle/budgets';
import {
  closure,
  familiesOnDisk,
  familyModule,
  screensOf,
  type AssetInfo,
  type ChunkInfo,
} from './bundle-report';

const FAMILIES = familiesOnDisk();

const chunk = (file: string, gzip: number, more: Partial<ChunkInfo> = {}): ChunkInfo => ({
  file,
  bytes: gzip * 3,
  gzip,
  entry: false,
  facade: null,
  imports: [],
  dynamicImports: [],
  css: [],
  ...more,
});

/** A build: an entry importing react and zod, the two pages, each family's module and first tab. */
function build(): { chunks: ChunkInfo[]; css: AssetInfo[] } {
  const chunks = [
    chunk('index.js', 100, { entry: true, imports: ['react.js', 'zod.js'], css: ['index.css'] }),
    chunk('react.js', 50),
    chunk('zod.js', 20),
    chunk('fleet.js', 5, { facade: 'src/app/FleetPage.tsx', imports: ['react.js'] }),
    chunk('machine.js', 6, { facade: 'src/app/MachinePage.tsx' }),
    chunk('kiosk.js', 3, { facade: 'src/app/kiosk/KioskPage.tsx' }),
    chunk('topbar.js', 2, { facade: 'src/app/TopBar.tsx' }),
    chunk('overrides.js', 1, { facade: 'src/controllers/g2core/views/KioskExtra.tsx' }),
    chunk('query.js', 11),
  ];
  for (const { kind, module, firstTab } of FAMILIES) {
    chunks.push(chunk(`${kind}.js`, 10, { facade: module, imports: ['query.js', 'zod.js'] }));
    chunks.push(chunk(`${kind}-tab.js`, 2, { facade: firstTab, css: [`${kind}.css`] }));
  }
  const css = [
    { file: 'index.css', bytes: 12, gzip: 4 },
    ...FAMILIES.map(({ kind }) => ({ file: `${kind}.css`, bytes: 3, gzip: 1 })),
  ];
  return { chunks, css };
}

describe('bundle report', () => {
  it("finds every family in src/controllers, and a kiosk view only where the family's manifest has one", () => {
    expect(FAMILIES.map((f) => f.kind)).toEqual(['duet', 'g2core', 'prunt', 'touchcut', 'xtool']);
    expect(FAMILIES.filter((f) => f.kioskExtra).map((f) => f.kioskExtra)).toEqual([
      'src/controllers/g2core/views/KioskExtra.tsx',
    ]);
  });

  it('follows static imports, each file once, with their CSS', () => {
    const { chunks } = build();
    const all = new Map(chunks.map((c) => [c.file, c]));
    expect([...closure(all, 'index.js')].sort()).toEqual(['index.css', 'index.js', 'react.js', 'zod.js']);
  });

  it('adds up each screen: shell, family (without the shell), machine page, fleet page', () => {
    const { chunks, css } = build();
    const s = Object.fromEntries(screensOf(chunks, css).map((x) => [x.name, x.gzip]));
    expect(s.shell).toBe(100 + 50 + 20 + 4);
    // The family's module and query-core; zod is the shell's already.
    expect(s['family: xtool']).toBe(10 + 11);
    // Shell, machine page, family, query, first tab and its CSS.
    expect(s['machine page: xtool']).toBe(174 + 6 + 2 + 10 + 11 + 2 + 1);
    // A kiosk's first screen: the machine page's route and the kiosk view, no family.
    expect(s['kiosk page: first screen']).toBe(174 + 6 + 3);
    // Live: with the family, no tab; g2core's with its kiosk view.
    expect(s['kiosk page, live: xtool']).toBe(174 + 6 + 3 + 10 + 11);
    expect(s['kiosk page, live: g2core']).toBe(174 + 6 + 3 + 10 + 11 + 1);
    // A shop of lasers only: shell, fleet page, one family and query.
    expect(s['fleet page, live tiles: xtool machines only']).toBe(174 + 5 + 2 + 10 + 11);
    // The fleet page's first screen: the shell and the fleet page, no family.
    expect(s['fleet page: first screen']).toBe(174 + 5 + 2);
    // Shell, fleet page, five families, query once.
    expect(s['fleet page, live tiles: all five families']).toBe(174 + 5 + 2 + 5 * 10 + 11);
  });

  it('fails loudly when a family or page has no chunk of its own', () => {
    const { chunks, css } = build();
    expect(() =>
      screensOf(
        chunks.filter((c) => c.facade !== familyModule('duet')),
        css,
      ),
    ).toThrow(/src\/controllers\/duet\/module.tsx/);
  });

  it('names the screens over budget, and screens without one', () => {
    const screens = [
      { name: 'shell', files: [], gzip: 131 * 1024, bytes: 0 },
      { name: 'family: xtool', files: [], gzip: 10 * 1024, bytes: 0 },
      { name: 'mystery', files: [], gzip: 1, bytes: 0 },
    ];
    const over = overBudget(screens, [
      { screen: /^shell$/, kib: 128 },
      { screen: /^family: /, kib: 28 },
    ]);
    expect(over).toEqual(['shell: 131.0 KiB gzip, over its 128 KiB budget', 'mystery: no budget']);
  });
});
