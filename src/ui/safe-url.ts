/**
 * URL checks for controller data: the one place that decides which controller-supplied URL may
 * reach the DOM as an image source, a link or a download.
 *
 * The console's origin carries every machine (`/machines/<id>/…`, proxied by the gateway) and the
 * console's own API (`/api/…`). A controller must never be able to point the browser, with the
 * user's session, at another machine or the API. So every URL is resolved exactly as the browser
 * would (`new URL(raw, base)`, which normalises `%2e%2e`, `\`, `//host`, tabs inside a scheme…)
 * and the *result* is checked, never the text:
 * - `resolveWithin`: same origin, http(s), and a path under the given prefix (a machine's
 *   `/machines/<id>/`, or a folder below it such as `/machines/<id>/uploads/`). For images and downloads.
 * - `safeExternalHref`: an external `https:` page (never the console's host, never a bare IP or
 *   a local name). For links, always rendered with `rel="noopener noreferrer"`.
 * - `imageDataUrl` / `isImageDataUrl`: a base64 `data:` URL of a raster image type (no SVG).
 * - `safeImageBlob`: a blob of a raster image type, before it becomes a `blob:` URL.
 *
 * Pure functions of strings (no imports): usable from forms/, fleet/ and every controller.
 */

/** Raster types only: an SVG opened as a document (new tab) runs script. */
export const IMAGE_TYPES = ['image/png', 'image/jpeg', 'image/gif', 'image/webp'] as const;
export type ImageType = (typeof IMAGE_TYPES)[number];

/** Used to resolve a path-only base when the page has no http(s) origin (Node, about:blank). */
const PLACEHOLDER_ORIGIN = 'http://console.invalid';

/**
 * ASCII control characters (the URL parser silently drops tab/newline, so `java\tscript:` reads
 * as `javascript:`) and backslashes (read as `/`): no URL we accept contains them.
 */
function suspicious(s: string): boolean {
  for (let i = 0; i < s.length; i++) {
    const c = s.charCodeAt(i);
    if (c < 0x20 || c === 0x7f || c === 0x5c) return true;
  }
  return false;
}

/**
 * A percent-encoded dot, slash, backslash or NUL left in the path after the browser has normalised
 * it (`..%2f`, `%2f..`): a proxy or server that decodes once would read it as a way out.
 */
const ENCODED_TRAVERSAL = /%(2e|2f|5c|00)/i;

/** The page's origin ("http://host:port"), or null when there is no http(s) page (Node, tests). */
export function pageOrigin(): string | null {
  if (typeof location === 'undefined') return null;
  try {
    const o = location.origin;
    return /^https?:\/\/[^/]+$/.test(o) ? o : null;
  } catch {
    return null;
  }
}

export interface WithinOptions {
  /** The page's origin, for a path-only `base`. Defaults to `pageOrigin()`. */
  origin?: string | null;
}

/**
 * `raw` resolved against `base` as the browser resolves it, or null unless the result is an
 * http(s) URL on the same origin as `base`, without user name or password, whose path lies
 * strictly below `base` taken as a folder (`/machines/p1` → `/machines/p1/…`) and keeps no
 * encoded dot, slash or backslash. The query is kept; the fragment is dropped.
 *
 * The answer has the form of `base`: path and query for a path-only base (`/machines/p1`),
 * an absolute URL for an absolute one (`http://host/machines/p1`).
 */
export function resolveWithin(raw: string, base: string, opts: WithinOptions = {}): string | null {
  const s = raw.trim();
  if (s === '' || suspicious(s)) return null;
  const pathOnly = base.startsWith('/') && !base.startsWith('//');
  if (!pathOnly && !/^https?:\/\//i.test(base)) return null;
  const origin = opts.origin === undefined ? pageOrigin() : opts.origin;
  const folder = base.endsWith('/') ? base : `${base}/`;
  let baseUrl: URL;
  let u: URL;
  try {
    baseUrl = new URL(folder, origin ?? PLACEHOLDER_ORIGIN);
    u = new URL(s, baseUrl);
  } catch {
    return null;
  }
  // The base itself must be a plain folder below the root: `/machines/..%2f` or `/` would widen
  // the scope to the whole console.
  const basePath = pathOnly ? folder : folder.replace(/^https?:\/\/[^/]+/i, '');
  if (basePath === '/' || baseUrl.pathname !== basePath || baseUrl.search !== '' || baseUrl.hash !== '')
    return null;
  // blob:/data:/javascript:… (a `blob:` URL has our origin, but its path never starts with "/")
  if (u.protocol !== 'http:' && u.protocol !== 'https:') return null;
  if (u.origin !== baseUrl.origin || u.username !== '' || u.password !== '') return null;
  const scope = baseUrl.pathname; // ends with "/"
  if (!u.pathname.startsWith(scope) || u.pathname.length === scope.length) return null;
  if (ENCODED_TRAVERSAL.test(u.pathname)) return null;
  return pathOnly ? u.pathname + u.search : `${u.origin}${u.pathname}${u.search}`;
}

/** Host names that name this network, not the internet. */
const LOCAL_HOST =
  /(^localhost$|\.localhost$|\.local$|\.lan$|\.home$|\.internal$|\.intranet$|\.corp$|\.home\.arpa$)/i;

/**
 * `raw` as an external `https:` link, or null. Refused: any other scheme (`http:`, `javascript:`,
 * `data:`, `blob:`, `mailto:`), relative URLs, user names or passwords in the URL, the console's
 * own host (whatever the port), IP addresses and names of the local network (`localhost`, no dot,
 * `.local`…): a link must not lead the user's browser to a machine on the shop floor.
 */
export function safeExternalHref(raw: string, origin: string | null = pageOrigin()): string | null {
  const s = raw.trim();
  if (s === '' || suspicious(s)) return null;
  let u: URL;
  try {
    u = new URL(s); // no base: a relative URL is not external
  } catch {
    return null;
  }
  if (u.protocol !== 'https:' || u.username !== '' || u.password !== '') return null;
  const host = u.hostname.toLowerCase();
  if (host === '' || !host.includes('.') || host.endsWith('.') || LOCAL_HOST.test(host)) return null;
  if (host.startsWith('[') || /^[\d.]+$/.test(host)) return null; // IP literals
  if (origin) {
    try {
      const own = new URL(origin);
      if (u.origin === own.origin || host === own.hostname.toLowerCase()) return null;
    } catch {
      return null;
    }
  }
  return u.href;
}

const BASE64 = /^[A-Za-z0-9+/]+={0,2}$/;
/** Thumbnails are small; a bigger "image" is not one. */
export const MAX_DATA_URL_CHARS = 4 * 1024 * 1024;

function imageType(type: string): ImageType | null {
  const t = type.split(';')[0]?.trim().toLowerCase() ?? '';
  return (IMAGE_TYPES as readonly string[]).includes(t) ? (t as ImageType) : null;
}

/** `data:<type>;base64,<data>` when the type is a raster image type and the data is base64; else null. */
export function imageDataUrl(type: string, base64: string): string | null {
  const t = imageType(type);
  if (!t || type.trim().toLowerCase() !== t) return null;
  const data = base64.replace(/[\t\n\f\r ]/g, '');
  if (data === '' || data.length > MAX_DATA_URL_CHARS || data.length % 4 === 1 || !BASE64.test(data))
    return null;
  return `data:${t};base64,${data}`;
}

/** Whether `url` is exactly a base64 `data:` URL of a raster image type (as `imageDataUrl` makes). */
export function isImageDataUrl(url: string): boolean {
  const m = /^data:([a-z/]+);base64,(.*)$/s.exec(url);
  return m !== null && imageDataUrl(m[1] ?? '', m[2] ?? '') === url;
}

/** The blob when its type is a raster image type, else null (an HTML or SVG "image" opened in a
 * new tab as a `blob:` URL would run in the console's origin). */
export function safeImageBlob(blob: Blob | null | undefined): Blob | null {
  if (!blob) return null;
  return imageType(blob.type) ? blob : null;
}
