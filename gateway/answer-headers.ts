import type { ServerResponse } from 'node:http';

/**
 * What a controller's answer may say to the browser. A controller is possibly hostile: its answer
 * is served on the console's origin, so it must never render as a page (markup runs script as the
 * console), set state for the console's origin (cookies, HSTS, Clear-Site-Data, service-worker
 * scope), grant other sites access (CORS) or send the browser elsewhere (Refresh, Link preloads).
 *
 * - Headers pass through an allow-list; everything else is dropped.
 * - Nothing from a machine is kept by the browser: every answer is `Cache-Control: no-store`, and
 *   the controller's own caching and validator headers (Cache-Control, Expires, ETag,
 *   Last-Modified, Age, Pragma) are dropped. A shared tablet must not answer the next person's
 *   request for a machine URL from its cache after a supervisor signed out (`forceNoStore` below
 *   holds every gateway answer, refusals and failures included, to the same rule).
 * - Every answer gets `Content-Security-Policy: sandbox; default-src 'none'` (a document opened
 *   from it has no script, no origin, no subresources) and `X-Content-Type-Options: nosniff`.
 * - HTML, XML, SVG, script and style types are served as `text/plain` (opened, they read as text);
 *   image types only where the family declares that the console shows the answer as an image
 *   (thumbnails, screenshots), and then only raster types; any other type that is not plain data
 *   becomes `application/octet-stream`, as an attachment.
 */

export const NO_STORE = 'no-store';

/** What would let a browser (or a proxy on the way) keep an answer or revalidate a kept one. */
const CACHING = ['cache-control', 'expires', 'etag', 'last-modified', 'age', 'pragma'];

export const ANSWER_CSP = "sandbox; default-src 'none'; frame-ancestors 'none'";

const PASS = new Set([
  'content-type',
  'content-length',
  'content-disposition',
  'content-range',
  'accept-ranges',
  'date',
  'vary',
  'retry-after',
  'location',
]);

/** Vendor headers (`X-…`) pass, except those that change how the browser treats the answer. */
const X_BLOCKED = new Set([
  'x-frame-options',
  'x-content-type-options',
  'x-xss-protection',
  'x-dns-prefetch-control',
  'x-permitted-cross-domain-policies',
  'x-download-options',
  'x-ua-compatible',
  // nginx's own caching instruction
  'x-accel-expires',
]);

/** Raster image types the console may show from a controller (never SVG: it is a document). */
const RASTER = /^image\/(png|jpeg|jpg|gif|webp|bmp|avif|x-icon|vnd\.microsoft\.icon|qoi)$/;

/** Data types served as they are (no markup, nothing a browser runs). */
const DATA =
  /^(application\/(json|problem\+json|octet-stream|gzip|zip|x-gcode|pdf)|text\/(plain|csv|x-gcode|tab-separated-values))$/;

/** Markup, script and style: shown as text, never as what they claim to be. */
const ACTIVE =
  /^(text\/(html|xml|javascript|ecmascript|css|xsl|vtt)|application\/(xhtml\+xml|xml|javascript|ecmascript|x-javascript|rss\+xml|atom\+xml|vnd\.wap\.xhtml\+xml)|image\/svg\+xml|[^/]+\/[^;]*\+xml)$/;

function mediaType(contentType: string): string {
  return (contentType.split(';')[0] ?? '').trim().toLowerCase();
}

export interface AnswerHeaderOptions {
  /** The family declares that the console shows this answer as an image. */
  image: boolean;
}

/**
 * The headers the browser gets for a controller's answer. `headers` has lower-case keys (Node's
 * `IncomingHttpHeaders` after hop-by-hop filtering).
 */
export function safeAnswerHeaders(
  headers: Readonly<Record<string, string | string[]>>,
  opts: AnswerHeaderOptions,
): Record<string, string | string[]> {
  const out: Record<string, string | string[]> = {};
  for (const [k, v] of Object.entries(headers)) {
    const key = k.toLowerCase();
    if (PASS.has(key) || (key.startsWith('x-') && !X_BLOCKED.has(key) && !key.startsWith('x-shopdeck')))
      out[key] = v;
  }
  const given = typeof out['content-type'] === 'string' ? out['content-type'] : '';
  const type = mediaType(given);
  const attachment = (): void => {
    if (typeof out['content-disposition'] !== 'string' || !/^attachment/i.test(out['content-disposition']))
      out['content-disposition'] = 'attachment';
  };
  if (type === '') {
    // No type: never let the browser guess.
    out['content-type'] = 'application/octet-stream';
  } else if (RASTER.test(type)) {
    if (!opts.image) {
      out['content-type'] = 'application/octet-stream';
      attachment();
    }
  } else if (ACTIVE.test(type) || type.startsWith('image/')) {
    const charset = /charset=([\w-]+)/i.exec(given)?.[1];
    out['content-type'] = `text/plain; charset=${charset ?? 'utf-8'}`;
  } else if (!DATA.test(type)) {
    out['content-type'] = 'application/octet-stream';
    attachment();
  }
  out['cache-control'] = NO_STORE;
  out['content-security-policy'] = ANSWER_CSP;
  out['x-content-type-options'] = 'nosniff';
  out['cross-origin-resource-policy'] = 'same-origin';
  out['referrer-policy'] = 'no-referrer';
  return out;
}

type HeadersArg = Record<string, unknown> | unknown[];

function withoutCaching(h: HeadersArg): HeadersArg {
  if (Array.isArray(h)) {
    // Node's flat [name, value, name, value…] form, or [[name, value]…]
    if (h.length > 0 && Array.isArray(h[0]))
      return (h as unknown[][]).filter((pair) => !CACHING.includes(String(pair[0]).toLowerCase()));
    const out: unknown[] = [];
    for (let i = 0; i + 1 < h.length; i += 2)
      if (!CACHING.includes(String(h[i]).toLowerCase())) out.push(h[i], h[i + 1]);
    return out;
  }
  const out: Record<string, unknown> = {};
  for (const [k, v] of Object.entries(h)) if (!CACHING.includes(k.toLowerCase())) out[k] = v;
  return out;
}

/**
 * Holds one answer of the gateway (`/api/*`, `/machines/*`: proxied, simulated, refused or
 * failed) to `Cache-Control: no-store`, whoever writes its head and however: the caching and
 * validator headers are taken out of what is written (object or array form, `setHeader` before)
 * and `no-store` put in. gateway.ts applies it to every request it takes.
 */
export function forceNoStore(res: ServerResponse): void {
  const writeHead = res.writeHead.bind(res) as (status: number, ...rest: unknown[]) => ServerResponse;
  res.writeHead = ((status: number, ...rest: unknown[]): ServerResponse => {
    const at = typeof rest[0] === 'string' ? 1 : 0;
    const given = rest[at];
    if (given !== null && typeof given === 'object') rest[at] = withoutCaching(given as HeadersArg);
    if (!res.headersSent) {
      for (const name of CACHING) res.removeHeader(name);
      res.setHeader('Cache-Control', NO_STORE);
    }
    return writeHead(status, ...rest);
  }) as ServerResponse['writeHead'];
}
