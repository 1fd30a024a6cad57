import { availableParallelism } from 'node:os';
import { fileURLToPath } from 'node:url';
import { defineConfig } from 'vitest/config';

/**
 * Four projects (issue 34): `unit` (the page's code and the repository's own checks), `integration`
 * (the gateway and the server on real sockets, the scripts), `faults` (the fault matrix, run on
 * its own: it drives every family through every fault) and `bundle` (the size check and the
 * bundle guard, after `npm run build`). `npm test` runs unit and integration in one run, then the
 * matrix, then the bundle after the build (package.json).
 *
 * Workers: Vitest's default is one fewer than the cores, one on a 2-core machine; most of these
 * files wait on sockets and (fake or real) timers rather than compute, so two run side by side on
 * two cores (SHOPDECK_TEST_WORKERS to change it). Measured on this 2-core machine: see
 * docs/performance.md ("the test run").
 */
const workers = Number(process.env.SHOPDECK_TEST_WORKERS) || Math.max(2, availableParallelism());

export default defineConfig({
  // The page's zod/mini, configured as in the browser (vite.config.ts, src/zod-jitless.ts).
  resolve: {
    alias: [
      { find: /^zod\/mini$/, replacement: fileURLToPath(new URL('./src/zod-jitless.ts', import.meta.url)) },
    ],
  },
  test: {
    environment: 'node',
    setupFiles: ['tests/setup.ts'],
    testTimeout: 20_000,
    pool: 'forks',
    maxWorkers: workers,
    projects: [
      {
        extends: true,
        test: { name: 'unit', include: ['src/**/*.test.{ts,tsx}', 'tests/unit/**/*.test.{ts,tsx}'] },
      },
      {
        extends: true,
        test: {
          name: 'integration',
          include: [
            'gateway/**/*.test.ts',
            'server/**/*.test.ts',
            'scripts/**/*.test.ts',
            'tests/faults/**/*.test.ts',
          ],
          // The bundle guard reads dist/: it runs in `bundle`, after the build.
          exclude: ['tests/faults/matrix.test.ts', 'gateway/bundle.test.ts'],
        },
      },
      { extends: true, test: { name: 'faults', include: ['tests/faults/matrix.test.ts'] } },
      {
        extends: true,
        test: { name: 'bundle', include: ['tests/bundle/**/*.test.ts', 'gateway/bundle.test.ts'] },
      },
    ],
  },
});
