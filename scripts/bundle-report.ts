/**
 * The page's bundle report (issue 16), written by `vite build` into `bundle-report/bundle.json`
 * and `bundle-report/bundle.md` (not served): every chunk's size raw and gzip, and what each
 * screen loads — the shell (the entry and its static imports, with their CSS), each family's
 * code (its module chunk and what it imports), the fleet page (the shell and the families its
 * machines need: the demo fleet has all five; a shop of one family loads one) and a machine page (the shell, its family and the
 * first tab). `tests/bundle/budget.test.ts` fails when a screen grows past its ceiling.
 */
import { existsSync, mkdirSync, readdirSync, writeFileSync } from 'node:fs';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import zlib from 'node:zlib';
import type { Plugin } from 'vite';

/**
 * A family's files the report follows, by the convention every family keeps (README, "Adding a
 * controller family"): its page module, its first tab (`views/Overview.tsx`: what a machine page
 * shows first) and, if it has one, the view its kiosk shows under the job controls
 * (`views/KioskExtra.tsx`, its manifest's `kiosk.extra`). Tests keep the convention true.
 */
export interface FamilyFiles {
  kind: string;
  module: string;
  firstTab: string;
  kioskExtra: string | null;
}

export const familyModule = (kind: string): string => `src/controllers/${kind}/module.tsx`;
export const familyFirstTab = (kind: string): string => `src/controllers/${kind}/views/Overview.tsx`;
export const familyKioskExtra = (kind: string): string => `src/controllers/${kind}/views/KioskExtra.tsx`;

const PROJECT = fileURLToPath(new URL('..', import.meta.url));

/** The families: the folders of src/controllers (a family is its folder), with their files. */
export function familiesOnDisk(root = PROJECT): FamilyFiles[] {
  return readdirSync(path.join(root, 'src', 'controllers'), { withFileTypes: true })
    .filter((d) => d.isDirectory())
    .map((d) => d.name)
    .sort()
    .map((kind) => ({
      kind,
      module: familyModule(kind),
      firstTab: familyFirstTab(kind),
      kioskExtra: existsSync(path.join(root, familyKioskExtra(kind))) ? familyKioskExtra(kind) : null,
    }));
}

/** The route chunks (src/app/pages.ts). */
const FLEET_PAGE = 'src/app/FleetPage.tsx';
const MACHINE_PAGE = 'src/app/MachinePage.tsx';
const KIOSK_PAGE = 'src/app/kiosk/KioskPage.tsx';
/** The top bar: with every page but a kiosk tablet's. */
const TOP_BAR = 'src/app/TopBar.tsx';

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
export function screensOf(
  chunkList: ChunkInfo[],
  css: AssetInfo[],
  families: readonly FamilyFiles[] = familiesOnDisk(),
): Screen[] {
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
  for (const { kind, module, firstTab, kioskExtra } of families) {
    const mod = need(module);
    const withFamily = closure(chunks, mod.file, new Set(shell));
    out.push(
      screen(`fleet page, live tiles: ${kind} machines only`, closure(chunks, mod.file, new Set(fleetShell))),
    );
    closure(chunks, mod.file, fleet);
    const family = new Set([...withFamily].filter((f) => !shell.has(f)));
    out.push(screen(`family: ${kind}`, family));
    const page = closure(chunks, mod.file, new Set(machinePage));
    out.push(screen(`machine page: ${kind}`, closure(chunks, need(firstTab).file, page)));
    // Then, live, with its controls: the machine page's route, the kiosk view (no tabs), the
    // family and its kiosk view, if it has one.
    const kiosk = closure(chunks, need(KIOSK_PAGE).file, closure(chunks, mod.file, new Set(machineRoute)));
    out.push(
      screen(`kiosk page, live: ${kind}`, kioskExtra ? closure(chunks, need(kioskExtra).file, kiosk) : kiosk),
    );
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
      const report: BundleReport = { chunks, css, screens: screensOf(chunks, css, familiesOnDisk(root)) };
      mkdirSync(reportDir, { recursive: true });
      writeFileSync(path.join(reportDir, 'bundle.json'), `${JSON.stringify(report, null, 1)}\n`);
      writeFileSync(path.join(reportDir, 'bundle.md'), reportMarkdown(report));
    },
  };
}
