#!/usr/bin/env node
// Before the browser tests: make sure there is a Chromium to run them in. The system's
// (/usr/bin/chromium or PLAYWRIGHT_CHROMIUM_PATH, as playwright.config.ts uses), else
// Playwright's own; when neither is there, try to install Playwright's, and when that is
// impossible (no download allowed), say in one line what to run.
import { spawnSync } from 'node:child_process';
import { existsSync } from 'node:fs';

const system = process.env.PLAYWRIGHT_CHROMIUM_PATH ?? '/usr/bin/chromium';
if (existsSync(system)) process.exit(0);

async function playwrightHasOne() {
  try {
    const { chromium } = await import('@playwright/test');
    const p = chromium.executablePath();
    return Boolean(p) && existsSync(p);
  } catch {
    return false;
  }
}

if (await playwrightHasOne()) process.exit(0);
console.log('No Chromium for the browser tests: installing Playwright’s (npx playwright install chromium)…');
const r = spawnSync('npx', ['playwright', 'install', 'chromium'], { stdio: 'inherit' });
if (r.status === 0 && (await playwrightHasOne())) process.exit(0);
const apt = spawnSync('sh', ['-c', 'command -v apt-get'], { encoding: 'utf8' }).stdout.trim();
console.error(
  apt
    ? 'No browser for the browser tests: run `sudo apt-get install -y chromium` (or `npx playwright install chromium` where downloads work), then `npm test` again.'
    : 'No browser for the browser tests: install Chromium and set PLAYWRIGHT_CHROMIUM_PATH to it, or run `npx playwright install chromium`, then `npm test` again.',
);
process.exit(1);
