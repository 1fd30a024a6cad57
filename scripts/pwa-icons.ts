/**
 * Makes the installed app's PNG icons (public/icons/) from public/favicon.svg, offline: headless
 * Chromium (the one Playwright uses) draws each SVG and screenshots it. The PNGs are committed;
 * run this again after changing the favicon: `npx tsx scripts/pwa-icons.ts`.
 *
 * - icon-192.png, icon-512.png: the favicon as it is (rounded corners, transparent outside).
 * - icon-maskable-512.png: full-bleed background, the glyph inside the central safe zone (a
 *   launcher may cut the icon to a circle of 80 % of its size).
 * - apple-touch-icon.png (180): full-bleed, iOS rounds the corners itself.
 */
import { existsSync, mkdirSync, readFileSync } from 'node:fs';
import path from 'node:path';
import { chromium } from '@playwright/test';

const root = path.resolve(import.meta.dirname, '..');
const favicon = readFileSync(path.join(root, 'public', 'favicon.svg'), 'utf8');
const outDir = path.join(root, 'public', 'icons');

/** The favicon's background colour and glyph paths. */
const fill = /<rect[^>]*fill="([^"]+)"/.exec(favicon)?.[1];
const glyph = /<path[^>]*\/>/.exec(favicon)?.[0];
if (!fill || !glyph) throw new Error('public/favicon.svg: expected one <rect fill> and one <path>');

/** A full-bleed square with the glyph scaled about the centre (16, 16.5). */
const fullBleed = (scale: number): string =>
  `<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 32 32"><rect width="32" height="32" fill="${fill}"/>` +
  `<g transform="translate(16 16.5) scale(${scale}) translate(-16 -16.5)">${glyph}</g></svg>`;

const icons: Array<{ file: string; size: number; svg: string }> = [
  { file: 'icon-192.png', size: 192, svg: favicon },
  { file: 'icon-512.png', size: 512, svg: favicon },
  { file: 'icon-maskable-512.png', size: 512, svg: fullBleed(0.75) },
  { file: 'apple-touch-icon.png', size: 180, svg: fullBleed(0.9) },
];

const executablePath =
  process.env.PLAYWRIGHT_CHROMIUM_PATH ?? (existsSync('/usr/bin/chromium') ? '/usr/bin/chromium' : undefined);
const browser = await chromium.launch({
  ...(executablePath ? { executablePath } : {}),
  args: ['--no-sandbox', '--disable-gpu'],
});
try {
  mkdirSync(outDir, { recursive: true });
  for (const icon of icons) {
    const page = await browser.newPage({ viewport: { width: icon.size, height: icon.size } });
    const src = `data:image/svg+xml;base64,${Buffer.from(icon.svg).toString('base64')}`;
    await page.setContent(
      `<html><body style="margin:0;background:transparent"><img src="${src}" width="${icon.size}" height="${icon.size}" style="display:block"></body></html>`,
    );
    await page.locator('img').evaluate((img: HTMLImageElement) => img.decode());
    await page.screenshot({ path: path.join(outDir, icon.file), omitBackground: true });
    await page.close();
    console.log(`public/icons/${icon.file} (${icon.size}x${icon.size})`);
  }
} finally {
  await browser.close();
}
