import type { IncomingMessage, ServerResponse } from 'node:http';

/**
 * Security headers on every page and asset of the console itself (the controllers' answers get
 * their own, stricter ones: answer-headers.ts).
 *
 * - No inline script and no eval: a string from a controller that slips into the page cannot run.
 * - `frame-ancestors 'none'` and `X-Frame-Options: DENY`: no other page may frame the console
 *   (clickjacking a Stop or a setting).
 * - `connect-src 'self'`: the page talks to its own origin only (HTTP and WebSocket).
 * - `worker-src 'self'`, `manifest-src 'self'`: the installed console's service worker and web
 *   manifest (src/app/pwa/), from this origin only.
 * - Development (`npm run dev`) needs inline script for React's hot reload: there, and only
 *   there, `script-src` allows it.
 */
export function pageCsp(dev: boolean): string {
  return [
    "default-src 'self'",
    `script-src 'self'${dev ? " 'unsafe-inline'" : ''}`,
    // React and uPlot set styles through the CSSOM; inline style attributes stay allowed.
    "style-src 'self' 'unsafe-inline'",
    "img-src 'self' data: blob:",
    "connect-src 'self'",
    "worker-src 'self'",
    "font-src 'self'",
    "manifest-src 'self'",
    "media-src 'self' data: blob:",
    "object-src 'none'",
    "base-uri 'none'",
    "form-action 'self'",
    "frame-src 'none'",
    "frame-ancestors 'none'",
  ].join('; ');
}

/**
 * What logout tells the browser to forget (`Clear-Site-Data`), for the whole origin:
 *
 * - `"cache"`: the HTTP cache (and, in Chrome, the back/forward cache). Machine answers are
 *   `no-store` anyway (answer-headers.ts); this also drops whatever an older version kept.
 * - `"storage"`: localStorage (the forms' unsaved drafts of machine settings, src/forms/storage.ts;
 *   view and theme preferences go too), sessionStorage, IndexedDB, Cache Storage, and the service
 *   worker's registration. The service worker caches only the app shell (src/app/pwa/options.ts:
 *   no runtime caching, never `/api` or `/machines`), but a supervisor's drafts are machine data.
 *   Unregistering costs nothing lasting: the page goes to `/login` right after logout (a full
 *   load from the server, which has just answered), and that load registers the worker again and
 *   precaches the shell, so an installed or kiosk tablet still starts offline.
 *
 * Not `"cookies"`: the session cookie is already expired by the same answer, and clearing
 * cookies would end the sessions of other tabs' users on the same origin only by accident.
 * Browsers honour Clear-Site-Data in secure contexts only (HTTPS, or localhost).
 */
export const LOGOUT_CLEAR_SITE_DATA = '"cache", "storage"';

export function pageHeaders(dev: boolean): Record<string, string> {
  return {
    'Content-Security-Policy': pageCsp(dev),
    'X-Frame-Options': 'DENY',
    'X-Content-Type-Options': 'nosniff',
    'Referrer-Policy': 'no-referrer',
    'Cross-Origin-Opener-Policy': 'same-origin',
    'Cross-Origin-Resource-Policy': 'same-origin',
    'Permissions-Policy': 'camera=(), microphone=(), geolocation=(), payment=(), usb=(), serial=()',
  };
}

/**
 * Connect middleware: sets the page headers on every response (the gateway's own answers override
 * them with theirs) and, in production, refuses source maps.
 */
export function pageHeadersMiddleware(dev: boolean) {
  const headers = pageHeaders(dev);
  return (req: IncomingMessage, res: ServerResponse, next: () => void): void => {
    for (const [k, v] of Object.entries(headers)) res.setHeader(k, v);
    if (!dev && /\.map(?:$|[?#])/i.test(req.url ?? '')) {
      res.statusCode = 404;
      res.setHeader('Content-Type', 'text/plain; charset=utf-8');
      res.end('not found');
      return;
    }
    next();
  };
}
