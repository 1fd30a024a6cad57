/**
 * The page's bundle report (issue 16), written by `vite build` into `bundle-report/bundle.json`
 * and `bundle-report/bundle.md` (not served): every chunk's size raw and gzip, and what each
 * screen loads — the shell (the entry and its static imports, with their CSS), each family's
 * code (its module chunk and what it imports), the fleet page (the shell and the families its
 * machines need: the demo fleet has all five; a shop of one family loads one) and a machine page (the shell, its family and the
 * first tab). `tests/bundle/budget.test.ts` fails when a screen grows past its ceiling.
 */
import { mkdirSync, writeFileSync } from 'node:fs';
import path from 'node:path';
import zlib from 'node:zlib';
import type { Plugin } from 'vite';
import { MACHINE_KINDS, type MachineKind } from '../src/fleet/types';

/** Each family's first tab (what a machine page shows first); a test keeps this true. */
export const FIRST_TAB_VIEWS: Record<MachineKind, string> = {
  touchcut: 'src/controllers/touchcut/views/StatusView.tsx',
  g2core: 'src/controllers/g2core/views/Overview.tsx',
  duet: 'src/controllers/duet/views/Overview.tsx',
  xtool: 'src/controllers/xtool/views/Overview.tsx',
  prunt: 'src/controllers/prunt/views/OverviewTab.tsx',
};

export const familyModule = (kind: MachineKind): string => `src/controllers/${kind}/module.tsx`;

/** The route chunks (src/app/pages.ts). */
const FLEET_PAGE = 'src/app/FleetPage.tsx';
const MACHINE_PAGE = 'src/app/MachinePage.tsx';
const KIOSK_PAGE = 'src/app/kiosk/KioskPage.tsx';
/** The top bar: with every page but a kiosk tablet's. */
const TOP_BAR = 'src/app/TopBar.tsx';
/** The view a family's kiosk page shows below its controls (src/app/kiosk/per-family.ts). */
export const KIOSK_EXTRA_VIEWS: Partial<Record<MachineKind, string>> = {
  g2core: 'src/controllers/g2core/views/Overrides.tsx',
};

export interface ChunkInfo {
  file: string;
  bytes: number;
  gzip: number;
  entry: boolean;
  /** The source module the chunk stands for (relative), when it has one. */
  facade: string | null;
  imports: string[];
  dynamicImports: string[];
  css: string[];
}

export interface AssetInfo {
  file: string;
  bytes: number;
  gzip: number;
}

export interface Screen {
  name: string;
  /** JS and CSS files, each once. */
  files: string[];
  gzip: number;
  bytes: number;
}

export interface BundleReport {
  chunks: ChunkInfo[];
  css: AssetInfo[];
  screens: Screen[];
}

export const gzipSize = (data: string | Uint8Array): number =>
  zlib.gzipSync(data, { level: zlib.constants.Z_BEST_COMPRESSION }).length;

/** The files a chunk needs before it runs: itself, its static imports (transitively) and their CSS. */
export function closure(
  chunks: ReadonlyMap<string, ChunkInfo>,
  start: string,
  into = new Set<string>(),
): Set<string> {
  const c = chunks.get(start);
  if (!c || into.has(start)) return into;
  into.add(start);
  for (const css of c.css) into.add(css);
  for (const i of c.imports) closure(chunks, i, into);
  return into;
}

/** The screens of the report, from the chunks and CSS assets of one build. */
export function screensOf(chunkList: ChunkInfo[], css: AssetInfo[]): Screen[] {
  const chunks = new Map(chunkList.map((c) => [c.file, c]));
  const size = new Map<string, AssetInfo>([...chunkList, ...css].map((a) => [a.file, a]));
  const screen = (name: string, files: Set<string>): Screen => {
    const list = [...files].sort();
    const sum = (k: 'gzip' | 'bytes'): number => list.reduce((n, f) => n + (size.get(f)?.[k] ?? 0), 0);
    return { name, files: list, gzip: sum('gzip'), bytes: sum('bytes') };
  };
  const byFacade = (facade: string): ChunkInfo | undefined => chunkList.find((c) => c.facade === facade);
  const entry = chunkList.find((c) => c.entry);
  if (!entry) throw new Error('bundle report: the build has no entry chunk');
  const need = (facade: string): ChunkInfo => {
    const c = byFacade(facade);
    if (!c) throw new Error(`bundle report: no chunk for ${facade}`);
    return c;
  };
  const shell = closure(chunks, entry.file);
  const out: Screen[] = [screen('shell', shell)];
  const fleetShell = closure(
    chunks,
    need(FLEET_PAGE).file,
    closure(chunks, need(TOP_BAR).file, new Set(shell)),
  );
  // The fleet page paints its tiles from the console server's readings (src/app/first-screen.ts)
  // before any family's code; the families' code then loads at idle and makes the tiles live.
  out.push(screen('fleet page: first screen', fleetShell));
  const fleet = new Set(fleetShell);
  const machineRoute = closure(chunks, need(MACHINE_PAGE).file, new Set(shell));
  // A kiosk tablet (`/m/<id>?kiosk`) paints its machine from the console server's reading too
  // (KioskPage, first-screen.ts): the machine page's route and the kiosk view, no family yet.
  out.push(screen('kiosk page: first screen', closure(chunks, need(KIOSK_PAGE).file, new Set(machineRoute))));
  const machinePage = closure(chunks, need(TOP_BAR).file, new Set(machineRoute));
  for (const kind of MACHINE_KINDS) {
    const mod = need(familyModule(kind));
    const withFamily = closure(chunks, mod.file, new Set(shell));
    out.push(
      screen(`fleet page, live tiles: ${kind} machines only`, closure(chunks, mod.file, new Set(fleetShell))),
    );
    closure(chunks, mod.file, fleet);
    const family = new Set([...withFamily].filter((f) => !shell.has(f)));
    out.push(screen(`family: ${kind}`, family));
    const page = closure(chunks, mod.file, new Set(machinePage));
    out.push(screen(`machine page: ${kind}`, closure(chunks, need(FIRST_TAB_VIEWS[kind]).file, page)));
    // Then, live, with its controls: the machine page's route, the kiosk view (no tabs), the
    // family and its kiosk view, if it has one.
    const kiosk = closure(chunks, need(KIOSK_PAGE).file, closure(chunks, mod.file, new Set(machineRoute)));
    const extra = KIOSK_EXTRA_VIEWS[kind];
    out.push(screen(`kiosk page, live: ${kind}`, extra ? closure(chunks, need(extra).file, kiosk) : kiosk));
  }
  out.push(screen('fleet page, live tiles: all five families', fleet));
  return out;
}

const KiB = (n: number): string => (n / 1024).toFixed(1);

export function reportMarkdown(r: BundleReport): string {
  return [
    '# Bundle report',
    '',
    'gzip sizes of the JS and CSS each screen needs (`npm run build` writes this).',
    '',
    '| screen | files | gzip KiB | raw KiB |',
    '|---|---|---|---|',
    ...r.screens.map((s) => `| ${s.name} | ${s.files.length} | ${KiB(s.gzip)} | ${KiB(s.bytes)} |`),
    '',
    '| chunk | gzip KiB | raw KiB | stands for |',
    '|---|---|---|---|',
    ...[...r.chunks, ...r.css]
      .sort((a, b) => b.gzip - a.gzip)
      .map(
        (c) =>
          `| ${c.file} | ${KiB(c.gzip)} | ${KiB(c.bytes)} | ${'facade' in c ? (c.facade ?? '') : 'css'} |`,
      ),
    '',
  ].join('\n');
}

/**
 * The Vite plugin: after the bundle is written, the report in `bundle-report/` beside the output
 * folder (`dist/` → the project's `bundle-report/`; a test's build in a temporary folder writes
 * its own there, never over the project's). `outDir` overrides the place.
 */
export function bundleReport(outDir?: string): Plugin {
  let root = process.cwd();
  let reportDir = outDir ?? '';
  return {
    name: 'shopdeck-bundle-report',
    apply: 'build',
    configResolved(config) {
      root = config.root;
      reportDir = outDir ?? path.resolve(root, config.build.outDir, '..', 'bundle-report');
    },
    writeBundle(_options, bundle) {
      const chunks: ChunkInfo[] = [];
      const css: AssetInfo[] = [];
      for (const [file, out] of Object.entries(bundle)) {
        if (out.type === 'chunk') {
          chunks.push({
            file,
            bytes: Buffer.byteLength(out.code),
            gzip: gzipSize(out.code),
            entry: out.isEntry,
            facade: out.facadeModuleId ? path.relative(root, out.facadeModuleId) : null,
            imports: out.imports,
            dynamicImports: out.dynamicImports,
            css: [...(out.viteMetadata?.importedCss ?? [])],
          });
        } else if (file.endsWith('.css')) {
          const data = typeof out.source === 'string' ? out.source : out.source;
          css.push({ file, bytes: Buffer.byteLength(data), gzip: gzipSize(data) });
        }
      }
      const report: BundleReport = { chunks, css, screens: screensOf(chunks, css) };
      mkdirSync(reportDir, { recursive: true });
      writeFileSync(path.join(reportDir, 'bundle.json'), `${JSON.stringify(report, null, 1)}\n`);
      writeFileSync(path.join(reportDir, 'bundle.md'), reportMarkdown(report));
    },
  };
}
