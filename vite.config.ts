import react from '@vitejs/plugin-react';
import { fileURLToPath } from 'node:url';
import { defineConfig } from 'vite';
import { VitePWA } from 'vite-plugin-pwa';
import { shopdeckGateway } from './gateway/plugin';
import { bundleReport } from './scripts/bundle-report';
import { pwaOptions } from './src/app/pwa/options';

// The gateway is a Vite plugin: the same code serves `npm run dev` and `npm start` (vite preview).
export default defineConfig({
  // The bundle report (bundle-report/bundle.{json,md}): sizes of what each screen loads.
  // VitePWA: the web manifest and the service worker, in builds only (src/app/pwa/options.ts).
  plugins: [react(), shopdeckGateway(), bundleReport(), VitePWA(pwaOptions)],
  // zod/mini with `jitless` and English messages set before any schema exists, in every chunk
  // (src/zod-jitless.ts; vitest.config.ts has the same alias).
  resolve: {
    alias: [
      { find: /^zod\/mini$/, replacement: fileURLToPath(new URL('./src/zod-jitless.ts', import.meta.url)) },
    ],
  },
  server: { port: Number(process.env.SHOPDECK_PORT ?? 5173), host: process.env.SHOPDECK_HOST ?? 'localhost' },
  preview: {
    port: Number(process.env.SHOPDECK_PORT ?? 4173),
    host: process.env.SHOPDECK_HOST ?? 'localhost',
  },
  // No source maps in the served build (they would publish the sources); `npm run dev` has its own.
  build: { sourcemap: false, chunkSizeWarningLimit: 2000 },
});
