import { existsSync, mkdirSync, mkdtempSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import { defineConfig, devices } from '@playwright/test';

// Machines here cannot download browsers: use the system Chromium when there is one.
const executablePath =
  process.env.PLAYWRIGHT_CHROMIUM_PATH ?? (existsSync('/usr/bin/chromium') ? '/usr/bin/chromium' : undefined);
const launchOptions = {
  ...(executablePath ? { executablePath } : {}),
  args: ['--no-sandbox', '--disable-gpu', '--disable-background-networking', '--disable-component-update'],
};

const port = Number(process.env.SHOPDECK_E2E_PORT ?? 4180);
// Each run gets its own data folder (audit log), so tests never see another run's entries.
// (scripts/e2e.mjs runs the two projects side by side, each with its own port and folder.)
const given = process.env.SHOPDECK_E2E_DATA;
if (given) mkdirSync(given, { recursive: true });
const dataDir = given || mkdtempSync(join(tmpdir(), 'shopdeck-e2e-'));
process.env.SHOPDECK_E2E_DATA = dataDir;

export default defineConfig({
  testDir: 'tests/e2e',
  timeout: 60_000,
  expect: { timeout: 15_000 },
  fullyParallel: false,
  workers: 1,
  // One retry: these 2-core machines are shared and noisy, and a run that fails on one timing
  // fails the whole submission. A test that fails twice fails; one that passed on its retry is
  // reported "flaky" and named again at the end of the run (scripts/e2e.mjs), to be looked into.
  retries: 1,
  reporter: process.env.CI ? [['list']] : [['list']],
  use: {
    baseURL: `http://127.0.0.1:${port}`,
    trace: 'retain-on-failure',
    // The installed app's service worker is tested in pwa.spec.ts (which allows it); elsewhere it
    // would only add a precache download to every fresh browser context.
    serviceWorkers: 'block',
    screenshot: 'only-on-failure',
    launchOptions,
  },
  projects: [
    {
      name: 'tablet',
      use: {
        ...devices['Desktop Chrome'],
        viewport: { width: 1024, height: 768 },
        hasTouch: true,
        launchOptions,
      },
    },
    {
      name: 'desktop',
      use: { ...devices['Desktop Chrome'], viewport: { width: 1440, height: 900 }, launchOptions },
    },
  ],
  webServer: {
    // The production server (server/main.ts) serving the built dist/, not `vite preview`.
    command: `node --import tsx server/main.ts --port ${port} --host 127.0.0.1`,
    url: `http://127.0.0.1:${port}/api/machines`,
    reuseExistingServer: false,
    timeout: 60_000,
    env: { SHOPDECK_DATA: dataDir, SHOPDECK_MACHINES: 'tests/e2e/demo-machines.json' },
  },
});
