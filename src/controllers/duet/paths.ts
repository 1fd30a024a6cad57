/** Duet paths as DSF resolves them, the job folder and the height map (access.ts reads them). */

/** Default job directory; uploads there are operator work, its files are readable by viewers. */
export const JOBS_DIR = '0:/gcodes/';

/** The height map the height-map view reads (`move.compensation.file`, default). */
export const HEIGHT_MAP = '0:/sys/heightmap.csv';

/** C0 and C1 control characters: .NET's `(.*)` stops at a newline, RRF drops lines at 0x7F. */
// eslint-disable-next-line no-control-regex
export const CONTROL = /[\u0000-\u001f\u007f-\u009f]/;

/**
 * A RepRapFirmware/FatFs path in the one form DSF resolves it to (`FilePath.ToPhysical`): `\` is a
 * separator; `<n>:` names a drive (ASCII digits, `00:` is `0:`), else drive 0; empty and `.`
 * segments dropped, `..` resolved. Null when not certain: control characters, `..` above the root,
 * an absolute host path (`//etc/…`), non-ASCII drive digits. Case is kept (compared exactly).
 */
export function normaliseDuetPath(raw: string): string | null {
  if (CONTROL.test(raw)) return null;
  const p = raw.replace(/\\/g, '/');
  let drive = 0;
  let rest: string;
  const m = /^(\d+):\/*(.*)$/.exec(p);
  if (m) {
    const digits = m[1] ?? '';
    if (digits.length > 9) return null; // int.TryParse fails: DSF would read a folder named "…:"
    drive = Number(digits);
    rest = m[2] ?? '';
  } else if (/^\p{Nd}+:/u.test(p)) {
    return null; // .NET's \d matches these digits, int.TryParse does not
  } else if (p.startsWith('/')) {
    rest = p.slice(1);
    if (rest.startsWith('/')) return null; // Path.Combine(base, "/etc/…") is the host's /etc
  } else {
    rest = p;
  }
  const out: string[] = [];
  for (const seg of rest.split('/')) {
    if (seg === '' || seg === '.') continue;
    if (seg === '..') {
      if (out.length === 0) return null;
      out.pop();
      continue;
    }
    out.push(seg);
  }
  return `${drive}:/${out.join('/')}`;
}

/** A file (not the folder itself) under `0:/gcodes/`. */
export function isJobFile(path: string): boolean {
  const n = normaliseDuetPath(path);
  return n !== null && n.startsWith(JOBS_DIR) && n.length > JOBS_DIR.length;
}

/** Files viewers and operators may read: job files and the height map. */
export function openToViewers(path: string): boolean {
  return isJobFile(path) || normaliseDuetPath(path) === HEIGHT_MAP;
}
