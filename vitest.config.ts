import { fileURLToPath } from 'node:url';
import { defineConfig } from 'vitest/config';

export default defineConfig({
  // The page's zod/mini, configured as in the browser (vite.config.ts, src/zod-jitless.ts).
  resolve: {
    alias: [
      { find: /^zod\/mini$/, replacement: fileURLToPath(new URL('./src/zod-jitless.ts', import.meta.url)) },
    ],
  },
  test: {
    include: [
      'src/**/*.test.{ts,tsx}',
      'gateway/**/*.test.ts',
      'server/**/*.test.ts',
      'tests/unit/**/*.test.{ts,tsx}',
      'tests/faults/**/*.test.ts',
      'tests/bundle/**/*.test.ts',
      'scripts/**/*.test.ts',
    ],
    environment: 'node',
    setupFiles: ['tests/setup.ts'],
    testTimeout: 20_000,
    pool: 'forks',
  },
});
