/**
 * Canonical controller paths. The gateway classifies a request by its path (access policy)
 * and must forward exactly what it classified, so `/cnc//data`, `/cnc/./data` or `/cnc/%64ata`
 * cannot slip past a rule written for `/cnc/data`.
 */

const PCHAR_KEEP: Record<string, string> = {
  '%3A': ':',
  '%40': '@',
  '%24': '$',
  '%26': '&',
  '%2B': '+',
  '%2C': ',',
  '%3B': ';',
  '%3D': '=',
};

function encodeSegment(seg: string): string {
  return encodeURIComponent(seg).replace(/%(3A|40|24|26|2B|2C|3B|3D)/g, (m) => PCHAR_KEEP[m] ?? m);
}

/**
 * Decodes each segment, drops empty and `.` segments, resolves `..` (never above the root) and
 * re-encodes in one canonical form. A trailing slash is kept. Null when the path is not valid
 * percent-encoding.
 */
export function canonicalPath(raw: string): string | null {
  const segs = raw.split('/');
  const out: string[] = [];
  for (let i = 1; i < segs.length; i++) {
    let seg: string;
    try {
      seg = decodeURIComponent(segs[i] ?? '');
    } catch {
      return null;
    }
    const last = i === segs.length - 1;
    if (seg === '' && !last) continue;
    if (seg === '.') {
      if (last) out.push('');
      continue;
    }
    if (seg === '..') {
      out.pop();
      if (last) out.push('');
      continue;
    }
    out.push(encodeSegment(seg));
  }
  return '/' + out.join('/');
}

/** Query parameters whose values are credentials: never written to the audit log. */
const CREDENTIAL_PARAM =
  /^(password|pass|passwd|pwd|pin|key|apikey|api_key|sessionkey|token|access_token|secret)$/i;

/**
 * The path and query as the audit log shows them: credential parameters (a Duet password typed
 * into the login form, a session key) are replaced by `[redacted]`, whatever their value.
 */
export function auditTarget(t: { path: string; rawQuery: string }): string {
  if (!t.rawQuery) return t.path;
  const parts = t.rawQuery.split('&').map((p) => {
    const i = p.indexOf('=');
    const k = i < 0 ? p : p.slice(0, i);
    let name = k;
    try {
      name = decodeURIComponent(k);
    } catch {
      /* keep as is */
    }
    return CREDENTIAL_PARAM.test(name) && i >= 0 ? `${k}=[redacted]` : p;
  });
  return `${t.path}?${parts.join('&')}`;
}

export interface SplitTarget {
  /** Canonical path, starts with "/" */
  path: string;
  /** Raw query string without "?", "" when none */
  rawQuery: string;
  query: URLSearchParams;
}

export type SplitResult = SplitTarget | { error: string };

/**
 * What may stand in a request target as it is sent upstream (RFC 9112 §3.2: printable ASCII, no
 * space): anything else must come percent-encoded. Node's `http.request` throws on a space or a
 * control character, or on a character above U+00FF, and would send a byte from U+0080 to U+00FF
 * raw: both are refused here, whatever way the target came (HTTP, the read socket, the watch).
 */
const TARGET_CHARS = /^[\x21-\x7e]*$/;

/**
 * Splits "/a/b?x=1" (the part after `/machines/<id>`). Refuses a query with a repeated key:
 * a family reads the first value, a controller may act on the last. Refuses a target with a
 * character that cannot be sent as it is (a space, a control, anything not ASCII): it must come
 * percent-encoded, as a browser sends it.
 */
export function splitTarget(rest: string): SplitResult {
  if (!TARGET_CHARS.test(rest))
    return { error: 'the request target has a space, a control or a non-ASCII character: percent-encode it' };
  const hash = rest.indexOf('#');
  const noHash = hash >= 0 ? rest.slice(0, hash) : rest;
  const q = noHash.indexOf('?');
  const rawPath = q >= 0 ? noHash.slice(0, q) : noHash;
  const rawQuery = q >= 0 ? noHash.slice(q + 1) : '';
  const path = canonicalPath(rawPath.startsWith('/') ? rawPath : '/' + rawPath);
  if (path === null) return { error: 'the path is not valid percent-encoding' };
  let query: URLSearchParams;
  try {
    query = new URLSearchParams(rawQuery);
    for (const [k] of query) decodeURIComponent(k);
  } catch {
    return { error: 'the query is not valid percent-encoding' };
  }
  const keys = [...query.keys()];
  if (new Set(keys).size !== keys.length) return { error: 'a query parameter is repeated' };
  return { path, rawQuery, query };
}
