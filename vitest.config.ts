import { defineConfig } from 'vitest/config';

export default defineConfig({
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
