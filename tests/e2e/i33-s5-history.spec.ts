import { expect, test } from '@playwright/test';

/**
 * Issue 33, item 15: on a desktop (1440×900) the History page uses the width: two columns
 * (utilisation beside the stops), not one column several thousand pixels tall.
 */
test('History at desktop size: two columns, the page much shorter than one long column', async ({
  page,
}, info) => {
  test.skip(info.project.name !== 'desktop', 'desktop size (1440×900)');
  await page.goto('/history');
  await expect(page.getByTestId('history-page')).toBeVisible();
  const util = page.getByTestId('history-utilisation');
  const stops = page.getByTestId('history-stops');
  await expect(util).toBeVisible();
  await expect(stops).toBeVisible();
  const a = await util.boundingBox();
  const b = await stops.boundingBox();
  if (!a || !b) throw new Error('no boxes');
  // Side by side: the same row, stops to the right of utilisation.
  expect(Math.abs(a.y - b.y)).toBeLessThan(4);
  expect(b.x).toBeGreaterThan(a.x + a.width - 1);
  // The timeline and the jobs table keep the whole width.
  const tl = await page.getByTestId('history-timeline').boundingBox();
  expect(tl?.width ?? 0).toBeGreaterThan(1200);
  // Nothing wider than the window.
  const over = await page.evaluate(() => document.documentElement.scrollWidth - window.innerWidth);
  expect(over).toBeLessThanOrEqual(0);
  await page.screenshot({ path: '/tmp/s5-history.png', fullPage: true });
});
