import type { VitePWAOptions } from 'vite-plugin-pwa';

/**
 * The installable console (issue 17): the web manifest and the service worker, for
 * vite-plugin-pwa in vite.config.ts (build time only: nothing here runs in the page).
 *
 * - The service worker precaches the app shell: index.html, every JS and CSS chunk (each
 *   controller family's code too: an installed tablet must start offline and show its machine's
 *   page), the icons. Hashed assets need no revision; index.html gets one.
 * - Nothing else is cached: no runtime caching at all. `/api/…` (the gateway) and `/machines/…`
 *   (the controllers) always go to the network, and a navigation to them is never answered with
 *   the shell; so are `/healthz` and the CA download and its page. Logout's `Clear-Site-Data:
 *   "cache", "storage"` (gateway/page-headers.ts) unregisters this worker; the page's full load of
 *   `/login` right after registers it again.
 * - `autoUpdate`: a new version installs and takes over at once (skipWaiting, clientsClaim);
 *   the page then reloads itself when nobody is using it (register.ts). A kiosk tablet has
 *   nobody to answer a prompt, and old code against a new gateway must not last.
 */

/** Paths the service worker never answers (tested against pathname + search). */
export const NEVER_CACHED: RegExp[] = [
  /^\/api(?:[/?]|$)/,
  /^\/machines(?:[/?]|$)/,
  /^\/healthz(?:[/?]|$)/,
  // the CA download and its page (server/server.ts: HTTPS only, from the server every time)
  /^\/shopdeck-ca(?:\.crt)?(?:[?]|$)/,
];

/** Colours from src/ui/theme.css (light side): the top bar (--panel) and the page (--bg). */
export const THEME_COLOR = '#ffffff';
export const BACKGROUND_COLOR = '#eef1f5';

export const pwaOptions: Partial<VitePWAOptions> = {
  strategies: 'generateSW',
  // A minified worker without workbox's debug logging, whatever NODE_ENV the build runs under.
  mode: 'production',
  registerType: 'autoUpdate',
  // Registered by src/app/pwa/register.ts (production, secure context only), not by a script tag.
  injectRegister: false,
  filename: 'sw.js',
  manifestFilename: 'manifest.webmanifest',
  includeAssets: ['favicon.svg', 'icons/apple-touch-icon.png'],
  manifest: {
    id: '/',
    name: 'Shopdeck',
    short_name: 'Shopdeck',
    description: 'One console for a whole shop floor of machine controllers.',
    start_url: '/',
    scope: '/',
    display: 'standalone',
    theme_color: THEME_COLOR,
    background_color: BACKGROUND_COLOR,
    icons: [
      { src: '/icons/icon-192.png', sizes: '192x192', type: 'image/png', purpose: 'any' },
      { src: '/icons/icon-512.png', sizes: '512x512', type: 'image/png', purpose: 'any' },
      { src: '/icons/icon-maskable-512.png', sizes: '512x512', type: 'image/png', purpose: 'maskable' },
    ],
  },
  workbox: {
    // The icons and favicon come from includeAssets and the manifest's icons.
    globPatterns: ['**/*.{js,css,html}'],
    // Precompressed copies are written after the build; the server picks them by Accept-Encoding.
    globIgnores: ['**/*.map', '**/*.br', '**/*.gz', 'sw.js', 'workbox-*.js'],
    dontCacheBustURLsMatching: /^assets\//,
    navigateFallback: 'index.html',
    navigateFallbackDenylist: NEVER_CACHED,
    runtimeCaching: [],
    cleanupOutdatedCaches: true,
    clientsClaim: true,
    skipWaiting: true,
    // One file (sw.js, served no-cache) instead of sw.js plus a workbox-<hash>.js beside it.
    inlineWorkboxRuntime: true,
    sourcemap: false,
  },
  devOptions: { enabled: false },
};
