import { registerSW } from 'virtual:pwa-register';
import { startPwa } from './updates';

/** The chunk main.tsx loads when pwaWanted(): vite-plugin-pwa's registration, workbox-window. */
export function registerPwa(): void {
  startPwa(registerSW);
}
