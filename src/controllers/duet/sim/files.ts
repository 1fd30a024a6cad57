import type { JsonObject } from '../patch';
import { THUMB_JPEG, THUMB_PNG, THUMB_QOI } from './data/thumbnails';

/**
 * The simulator's virtual SD card: files and folders in memory, RRF paths ("0:/gcodes/a.gcode").
 * Job files carry slicer headers and thumbnail blocks in the PrusaSlicer format
 * (`; thumbnail begin WxH LEN`, `; thumbnail_JPG begin …`, `; thumbnail_QOI begin …`), and
 * `fileInfo` parses them back as DSF's file-info parser does.
 */

export interface MemFile {
  data: Uint8Array;
  modified: string;
}

const enc = new TextEncoder();
const dec = new TextDecoder();

export function normalize(path: string): string {
  let p = path.trim().replace(/\\/g, '/');
  if (!/^\d+:/.test(p)) p = `0:/${p.replace(/^\/+/, '')}`;
  p = p.replace(/\/+/g, '/');
  if (p.endsWith('/') && !/^\d+:\/$/.test(p)) p = p.slice(0, -1);
  return p;
}

export function parentOf(path: string): string | null {
  const p = normalize(path);
  if (/^\d+:\/?$/.test(p)) return null;
  const i = p.lastIndexOf('/');
  const parent = p.slice(0, i);
  return /^\d+:$/.test(parent) ? `${parent}/` : parent;
}

export class MemFs {
  readonly files = new Map<string, MemFile>();
  readonly dirs = new Map<string, string>();

  constructor(private readonly now: () => number) {
    this.dirs.set('0:/', iso(now()));
  }

  isDir(path: string): boolean {
    return this.dirs.has(normalize(path));
  }

  get(path: string): MemFile | undefined {
    return this.files.get(normalize(path));
  }

  mkdirs(path: string): void {
    const p = normalize(path);
    if (this.dirs.has(p)) return;
    const parent = parentOf(p);
    if (parent) this.mkdirs(parent);
    this.dirs.set(p, iso(this.now()));
  }

  write(path: string, data: Uint8Array | string, modified?: string): void {
    const p = normalize(path);
    const parent = parentOf(p);
    if (parent) this.mkdirs(parent);
    this.files.set(p, {
      data: typeof data === 'string' ? enc.encode(data) : data,
      modified: modified ?? iso(this.now()),
    });
  }

  text(path: string): string | null {
    const f = this.get(path);
    return f ? dec.decode(f.data) : null;
  }

  list(dir: string): Array<{ type: 'd' | 'f'; name: string; size?: number; date: string }> | null {
    const d = normalize(dir);
    if (!this.dirs.has(d)) return null;
    const prefix = d.endsWith('/') ? d : `${d}/`;
    const out: Array<{ type: 'd' | 'f'; name: string; size?: number; date: string }> = [];
    for (const [p, date] of this.dirs) {
      if (p !== d && p.startsWith(prefix) && !p.slice(prefix.length).includes('/'))
        out.push({ type: 'd', name: p.slice(prefix.length), date });
    }
    for (const [p, f] of this.files) {
      if (p.startsWith(prefix) && !p.slice(prefix.length).includes('/')) {
        out.push({ type: 'f', name: p.slice(prefix.length), size: f.data.byteLength, date: f.modified });
      }
    }
    return out.sort((a, b) => (a.type === b.type ? a.name.localeCompare(b.name) : a.type === 'd' ? -1 : 1));
  }

  /** Delete; 'notFound' | 'notEmpty' | 'ok'. */
  remove(path: string, recursive: boolean): 'ok' | 'notFound' | 'notEmpty' {
    const p = normalize(path);
    if (this.files.delete(p)) return 'ok';
    if (!this.dirs.has(p)) return 'notFound';
    const prefix = `${p}/`;
    const children = [...this.files.keys(), ...this.dirs.keys()].filter((k) => k.startsWith(prefix));
    if (children.length && !recursive) return 'notEmpty';
    for (const k of children) {
      this.files.delete(k);
      this.dirs.delete(k);
    }
    this.dirs.delete(p);
    return 'ok';
  }

  exists(path: string): boolean {
    const p = normalize(path);
    return this.files.has(p) || this.dirs.has(p);
  }

  move(from: string, to: string): void {
    const f = normalize(from);
    const t = normalize(to);
    const file = this.files.get(f);
    if (file) {
      this.files.delete(f);
      this.write(t, file.data, file.modified);
      return;
    }
    const prefix = `${f}/`;
    this.mkdirs(t);
    for (const [k, v] of [...this.dirs]) {
      if (k.startsWith(prefix)) {
        this.dirs.delete(k);
        this.dirs.set(t + k.slice(f.length), v);
      }
    }
    for (const [k, v] of [...this.files]) {
      if (k.startsWith(prefix)) {
        this.files.delete(k);
        this.files.set(t + k.slice(f.length), v);
      }
    }
    this.dirs.delete(f);
  }

  /** DSF's ParsedFileInfo of a G-code file. */
  fileInfo(path: string, withThumbnails: boolean): JsonObject | null {
    const p = normalize(path);
    const f = this.files.get(p);
    if (!f) return null;
    const text = dec.decode(f.data);
    return parseGcodeInfo(p, text, f.data.byteLength, f.modified, withThumbnails);
  }
}

export function iso(ms: number): string {
  return new Date(ms).toISOString().replace(/\.\d{3}Z$/, '');
}

export function parseGcodeInfo(
  fileName: string,
  text: string,
  size: number,
  lastModified: string,
  withThumbnails: boolean,
): JsonObject {
  const info: JsonObject = {
    fileName,
    size,
    lastModified,
    height: 0,
    layerHeight: 0,
    numLayers: 0,
    printTime: null,
    simulatedTime: null,
    generatedBy: null,
    filament: [],
    thumbnails: [],
  };
  const thumbs: JsonObject[] = [];
  const lines = text.split('\n');
  let offset = 0;
  let cur: {
    format: string;
    width: number;
    height: number;
    offset: number;
    size: number;
    data: string[];
  } | null = null;
  for (const raw of lines) {
    const line = raw.trim();
    const begin = /^;\s*thumbnail(?:_(JPG|QOI|PNG))?\s+begin\s+(\d+)x(\d+)\s+(\d+)/i.exec(line);
    if (begin) {
      const fmt = (begin[1] ?? 'PNG').toUpperCase();
      cur = {
        format: fmt === 'JPG' ? 'jpeg' : fmt === 'QOI' ? 'qoi' : 'png',
        width: Number(begin[2]),
        height: Number(begin[3]),
        offset: offset + raw.length + 1,
        size: Number(begin[4]),
        data: [],
      };
    } else if (cur && /^;\s*thumbnail(?:_\w+)?\s+end/i.test(line)) {
      thumbs.push({
        format: cur.format,
        width: cur.width,
        height: cur.height,
        offset: cur.offset,
        size: cur.size,
        data: withThumbnails ? cur.data.join('') : null,
      });
      cur = null;
    } else if (cur) {
      cur.data.push(line.replace(/^;\s*/, ''));
    } else if (line.startsWith(';')) {
      let m: RegExpExecArray | null;
      if ((m = /^;\s*generated by (.+)$/i.exec(line))) info['generatedBy'] = m[1] ?? null;
      else if ((m = /^;\s*layer_height\s*=\s*([\d.]+)/.exec(line))) info['layerHeight'] = Number(m[1]);
      else if ((m = /^;\s*max_layer_z\s*=\s*([\d.]+)/.exec(line))) info['height'] = Number(m[1]);
      else if ((m = /^;\s*total layers count\s*=\s*(\d+)/.exec(line))) info['numLayers'] = Number(m[1]);
      else if ((m = /^;\s*filament used \[mm\]\s*=\s*([\d.,\s]+)/.exec(line)))
        info['filament'] = (m[1] ?? '').split(',').map((s) => Number(s.trim()));
      else if ((m = /^;\s*estimated printing time \(normal mode\)\s*=\s*(.+)$/.exec(line)))
        info['printTime'] = parseDuration(m[1] ?? '');
    }
    offset += raw.length + 1;
  }
  info['thumbnails'] = thumbs;
  return info;
}

function parseDuration(s: string): number | null {
  let total = 0;
  let any = false;
  for (const m of s.matchAll(/(\d+)\s*([dhms])/g)) {
    any = true;
    const n = Number(m[1]);
    total += m[2] === 'd' ? n * 86400 : m[2] === 'h' ? n * 3600 : m[2] === 'm' ? n * 60 : n;
  }
  return any ? total : null;
}

function thumbBlock(kind: 'PNG' | 'JPG' | 'QOI', b64: string): string {
  const tag = kind === 'PNG' ? 'thumbnail' : `thumbnail_${kind}`;
  const rows: string[] = [];
  for (let i = 0; i < b64.length; i += 78) rows.push(`; ${b64.slice(i, i + 78)}`);
  return [`; ${tag} begin 48x48 ${b64.length}`, ...rows, `; ${tag} end`, ';', ''].join('\n');
}

function formatDuration(s: number): string {
  const h = Math.floor(s / 3600);
  const m = Math.floor((s % 3600) / 60);
  return `${h ? `${h}h ` : ''}${m}m ${s % 60}s`;
}

/** A plausible job file: header, thumbnail, `layers` layers of moves. */
export function makeJobFile(opts: {
  layers: number;
  layerHeight: number;
  printTime: number;
  filament: number;
  thumb: 'PNG' | 'JPG' | 'QOI';
  linesPerLayer?: number;
}): string {
  const thumb = opts.thumb === 'PNG' ? THUMB_PNG : opts.thumb === 'JPG' ? THUMB_JPEG : THUMB_QOI;
  const out: string[] = [
    '; generated by PrusaSlicer 2.7.1+linux-x64 on 2024-05-01 at 10:00:00 UTC',
    '',
    ';',
    thumbBlock(opts.thumb, thumb),
    `; estimated printing time (normal mode) = ${formatDuration(opts.printTime)}`,
    `; filament used [mm] = ${opts.filament.toFixed(1)}`,
    `; layer_height = ${opts.layerHeight}`,
    `; max_layer_z = ${(opts.layers * opts.layerHeight).toFixed(2)}`,
    `; total layers count = ${opts.layers}`,
    'M140 S60',
    'M104 S210',
    'G28',
    'M190 S60',
    'M109 S210',
  ];
  const per = opts.linesPerLayer ?? 120;
  let e = 0;
  for (let l = 1; l <= opts.layers; l++) {
    out.push(
      ';LAYER_CHANGE',
      `;Z:${(l * opts.layerHeight).toFixed(2)}`,
      `G1 Z${(l * opts.layerHeight).toFixed(2)} F720`,
    );
    for (let i = 0; i < per; i++) {
      const a = (i / per) * Math.PI * 2;
      e += 0.05;
      out.push(
        `G1 X${(115 + 40 * Math.cos(a)).toFixed(3)} Y${(105 + 30 * Math.sin(a)).toFixed(3)} E${e.toFixed(5)} F1800`,
      );
    }
  }
  out.push('M104 S0', 'M140 S0', 'G1 Z50 F600', 'M84', '');
  return out.join('\n');
}

const HEIGHTMAP = (() => {
  const rows: string[] = [];
  for (let y = 0; y < 6; y++) {
    const r: string[] = [];
    for (let x = 0; x < 7; x++)
      r.push(
        (0.06 * Math.sin(x * 0.9) + 0.04 * Math.cos(y * 1.1) - 0.02 + (x === 6 && y === 0 ? 0.05 : 0))
          .toFixed(3)
          .padStart(7),
      );
    rows.push(r.join(','));
  }
  return [
    'RepRapFirmware height map file v2 generated at 2024-05-01 10:00, mean error 0.031, deviation 0.052',
    'xmin,xmax,ymin,ymax,radius,xspacing,yspacing,xnum,ynum',
    '20.00,200.00,20.00,180.00,-1.00,30.00,32.00,7,6',
    ...rows,
    '',
  ].join('\n');
})();

export function seedFiles(fs: MemFs): void {
  const t = '2024-05-01T10:00:00';
  fs.write(
    '0:/gcodes/bracket.gcode',
    makeJobFile({ layers: 12, layerHeight: 0.2, printTime: 240, filament: 812.4, thumb: 'PNG' }),
    t,
  );
  fs.write(
    '0:/gcodes/gear.gcode',
    makeJobFile({ layers: 20, layerHeight: 0.15, printTime: 420, filament: 1530.2, thumb: 'JPG' }),
    t,
  );
  fs.write(
    '0:/gcodes/enclosure/lid.gcode',
    makeJobFile({ layers: 8, layerHeight: 0.3, printTime: 180, filament: 640, thumb: 'QOI' }),
    t,
  );
  fs.write('0:/macros/Heat bed 60C.g', 'M140 S60\n', t);
  fs.write('0:/macros/Park head.g', 'G91\nG1 Z10 F600\nG90\nG1 X0 Y200 F6000\n', t);
  fs.write('0:/macros/Filament/Purge line.g', 'G1 X10 Y10 Z0.3 F6000\nG1 X100 E15 F1000\n', t);
  fs.write(
    '0:/sys/config.g',
    '; Configuration file (simulated)\nM550 P"Simulated Duet"\nM584 X0.0 Y0.1 Z0.2 E0.3\nM669 K1 ; coreXY\n',
    t,
  );
  fs.write('0:/sys/homeall.g', 'G91\nG1 H1 X-240 Y-240 F3000\nG1 H1 Z-250 F360\nG90\n', t);
  fs.write('0:/sys/heightmap.csv', HEIGHTMAP, t);
  fs.write('0:/filaments/PLA/load.g', 'M109 S210\nG1 E50 F300\n', t);
  fs.write('0:/filaments/PLA/unload.g', 'M109 S210\nG1 E-60 F1200\n', t);
  fs.write('0:/filaments/PLA/config.g', 'M221 S100\n', t);
  fs.mkdirs('0:/firmware');
  fs.mkdirs('0:/www');
}
