/**
 * What a controller's answer may say to the browser. A controller is possibly hostile: its answer
 * is served on the console's origin, so it must never render as a page (markup runs script as the
 * console), set state for the console's origin (cookies, HSTS, Clear-Site-Data, service-worker
 * scope), grant other sites access (CORS) or send the browser elsewhere (Refresh, Link preloads).
 *
 * - Headers pass through an allow-list; everything else is dropped.
 * - Every answer gets `Content-Security-Policy: sandbox; default-src 'none'` (a document opened
 *   from it has no script, no origin, no subresources) and `X-Content-Type-Options: nosniff`.
 * - HTML, XML, SVG, script and style types are served as `text/plain` (opened, they read as text);
 *   image types only where the family declares that the console shows the answer as an image
 *   (thumbnails, screenshots), and then only raster types; any other type that is not plain data
 *   becomes `application/octet-stream`, as an attachment.
 */

export const ANSWER_CSP = "sandbox; default-src 'none'; frame-ancestors 'none'";

const PASS = new Set([
  'content-type',
  'content-length',
  'content-disposition',
  'content-range',
  'accept-ranges',
  'cache-control',
  'expires',
  'last-modified',
  'etag',
  'date',
  'age',
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
  out['content-security-policy'] = ANSWER_CSP;
  out['x-content-type-options'] = 'nosniff';
  out['cross-origin-resource-policy'] = 'same-origin';
  out['referrer-policy'] = 'no-referrer';
  return out;
}
