/**
 * Whether this page registers the service worker: production builds only (`npm run dev` has
 * none), in a secure context only (HTTPS, or localhost / 127.0.0.1: browsers refuse service
 * workers elsewhere), where the browser has them. The registration code itself is a chunk of
 * its own (register.ts), loaded only then.
 */
export interface PwaEnvironment {
  production: boolean;
  secureContext: boolean;
  serviceWorker: boolean;
}

export function pwaEnvironment(): PwaEnvironment {
  return {
    production: import.meta.env.PROD,
    secureContext: window.isSecureContext,
    serviceWorker: 'serviceWorker' in navigator,
  };
}

export function pwaWanted(env: PwaEnvironment = pwaEnvironment()): boolean {
  return env.production && env.secureContext && env.serviceWorker;
}
