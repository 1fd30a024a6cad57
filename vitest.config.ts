import { availableParallelism } from 'node:os';
import { fileURLToPath } from 'node:url';
import { defineConfig } from 'vitest/config';

/**
 * Four projects (issue 34): `unit` (the page's code and the repository's own checks), `integration`
 * (the gateway and the server on real sockets, the scripts), `faults` (the fault matrix, run on
 * its own: it drives every family through every fault) and `bundle` (the size check and the
 * bundle guard, after `npm run build`, and the packaging checks). `npm test` runs
 * unit and integration in one run, then the matrix, then the bundle after the build (package.json).
 *
 * Workers: Vitest's default is one fewer than the cores, one on a 2-core machine; most of these
 * files wait on sockets and (fake or real) timers rather than compute, so two run side by side on
 * two cores (SHOPDECK_TEST_WORKERS to change it). Measured on this 2-core machine: see
 * docs/performance.md ("the test run").
 */
const workers = Number(process.env.SHOPDECK_TEST_WORKERS) || Math.max(2, availableParallelism());

/**
 * Tests beside the page's code that need the real gateway, real sockets or a real device (a pty)
 * and wait on the wall clock: they run in `integration`, not `unit` (fake clock, no sockets).
 */
const SRC_ON_SOCKETS = [
  'src/controllers/*/server/gateway-serial.test.ts',
  'src/controllers/g2core/server/pty.test.ts',
  'src/controllers/xtool/server/discovery.test.ts',
  'src/controllers/touchcut/server/stats-pull.test.ts',
  'src/controllers/g2core/jobs-gateway.test.ts',
  'src/controllers/duet/gateway.test.ts',
  'src/controllers/duet/job-start.test.ts',
  'src/controllers/duet/standalone.test.ts',
  'src/controllers/duet/watch-standalone.test.ts',
];

/**
 * Packaging checks (issue 34): each makes its own production build or install in a temporary
 * folder (minutes of CPU on 2 cores). They run in `bundle`, after the build.
 */
const PACKAGING = [
  'tests/unit/bundle-content.test.ts',
  'gateway/dist-secrets.test.ts',
  'server/omit-dev.test.ts',
];

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
        test: {
          name: 'unit',
          include: ['src/**/*.test.{ts,tsx}', 'tests/unit/**/*.test.{ts,tsx}'],
          // One module graph per worker, not per file: these files hold no socket, server or
          // process, and each cleans up its fakes. Measured here (2 cores, 154 files, loaded):
          // 319 s and 299 CPU-s isolated, 232 s and 194 CPU-s not, every test passing in both.
          isolate: false,
          exclude: [...SRC_ON_SOCKETS, ...PACKAGING],
        },
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
            ...SRC_ON_SOCKETS,
          ],
          // The bundle guard reads dist/: it runs in `bundle`, after the build; so do the other
          // packaging checks (their own build, `npm ci --omit=dev`).
          exclude: ['tests/faults/matrix.test.ts', 'gateway/bundle.test.ts', ...PACKAGING],
        },
      },
      { extends: true, test: { name: 'faults', include: ['tests/faults/matrix.test.ts'] } },
      {
        extends: true,
        test: {
          name: 'bundle',
          include: ['tests/bundle/**/*.test.ts', 'gateway/bundle.test.ts', ...PACKAGING],
        },
      },
    ],
  },
});
