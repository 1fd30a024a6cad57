import { readdirSync, readFileSync, renameSync, rmSync, statSync, utimesSync, writeFileSync } from 'node:fs';
import path from 'node:path';
import { pathToFileURL } from 'node:url';
import { promisify } from 'node:util';
import zlib from 'node:zlib';

/**
 * Precompressed copies of the built console: `app-abc123.js.br` and `.gz` next to `app-abc123.js`,
 * made once after `vite build` so the server never compresses while it serves (sirv picks the
 * `.br`/`.gz` file when the browser accepts it). Idempotent: a copy is made again only when its
 * file changed (a copy carries its file's modification time, to the millisecond). Source maps are never compressed
 * (they are never served either).
 *
 *     tsx server/compress.ts [dist]
 */

/** Text types worth compressing; images, fonts and archives are compressed already. */
export const COMPRESSIBLE = /\.(?:m?js|css|html?|svg|json|webmanifest|txt|xml|wasm)$/i;

export interface CompressOptions {
  /** Smaller files are left alone (default 1024 bytes): the headers cost more than they save. */
  minSize?: number;
  /** Which encodings to write (default both). */
  encodings?: ReadonlyArray<'br' | 'gz'>;
}

export interface CompressResult {
  /** Copies written now, relative to the folder ("assets/app-abc123.js.br"). */
  written: string[];
  /** Copies already up to date. */
  upToDate: number;
  /** Copies not written because they were not smaller than the file. */
  notSmaller: string[];
  /** Bytes of the files that have copies, and of their brotli copies. */
  bytes: { original: number; br: number; gz: number };
}

const brotli = promisify(zlib.brotliCompress);
const gzip = promisify(zlib.gzip);

function walk(dir: string, out: string[] = []): string[] {
  for (const e of readdirSync(dir, { withFileTypes: true })) {
    const p = path.join(dir, e.name);
    if (e.isDirectory()) walk(p, out);
    else if (e.isFile()) out.push(p);
  }
  return out;
}

function mtimeOf(file: string): number | null {
  try {
    return statSync(file).mtimeMs;
  } catch {
    return null;
  }
}

async function encode(kind: 'br' | 'gz', data: Buffer): Promise<Buffer> {
  if (kind === 'gz') return gzip(data, { level: zlib.constants.Z_BEST_COMPRESSION });
  return brotli(data, {
    params: {
      [zlib.constants.BROTLI_PARAM_MODE]: zlib.constants.BROTLI_MODE_TEXT,
      [zlib.constants.BROTLI_PARAM_QUALITY]: zlib.constants.BROTLI_MAX_QUALITY,
      [zlib.constants.BROTLI_PARAM_SIZE_HINT]: data.length,
    },
  });
}

/** Writes the missing or stale `.br` and `.gz` copies of every compressible file under `dir`. */
export async function compressDist(dir: string, opts: CompressOptions = {}): Promise<CompressResult> {
  const minSize = opts.minSize ?? 1024;
  const encodings = opts.encodings ?? ['br', 'gz'];
  const result: CompressResult = {
    written: [],
    upToDate: 0,
    notSmaller: [],
    bytes: { original: 0, br: 0, gz: 0 },
  };
  const files = walk(path.resolve(dir)).filter((f) => COMPRESSIBLE.test(f) && !/\.map$/i.test(f));
  for (const file of files) {
    const st = statSync(file);
    if (st.size < minSize) continue;
    let data: Buffer | null = null;
    result.bytes.original += st.size;
    for (const kind of encodings) {
      const target = `${file}.${kind}`;
      const rel = path.relative(dir, target).split(path.sep).join('/');
      const copied = mtimeOf(target);
      if (copied !== null && Math.abs(copied - st.mtimeMs) < 1) {
        result.upToDate++;
        result.bytes[kind] += statSync(target).size;
        continue;
      }
      data ??= readFileSync(file);
      const packed = await encode(kind, data);
      if (packed.length >= data.length) {
        rmSync(target, { force: true });
        result.notSmaller.push(rel);
        continue;
      }
      // Written beside, then renamed: a server reading the folder never sees half a file.
      const tmp = `${target}.${process.pid}.tmp`;
      writeFileSync(tmp, packed);
      utimesSync(tmp, st.atimeMs / 1000, st.mtimeMs / 1000);
      renameSync(tmp, target);
      result.written.push(rel);
      result.bytes[kind] += packed.length;
    }
  }
  return result;
}

async function cli(argv: readonly string[]): Promise<void> {
  const dir = path.resolve(argv[0] ?? 'dist');
  const r = await compressDist(dir);
  const kb = (n: number): string => `${(n / 1024).toFixed(1)} KiB`;
  console.log(
    `shopdeck: precompressed ${dir}: ${r.written.length} written, ${r.upToDate} up to date` +
      (r.bytes.original ? ` (${kb(r.bytes.original)} → br ${kb(r.bytes.br)}, gzip ${kb(r.bytes.gz)})` : ''),
  );
}

if (process.argv[1] && import.meta.url === pathToFileURL(path.resolve(process.argv[1])).href) {
  cli(process.argv.slice(2)).catch((e: unknown) => {
    console.error(`shopdeck: cannot precompress: ${e instanceof Error ? e.message : String(e)}`);
    process.exit(1);
  });
}
