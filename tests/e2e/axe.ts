import AxeBuilder from '@axe-core/playwright';
import { expect, type Page, type TestInfo } from '@playwright/test';

const TAGS = ['wcag2a', 'wcag2aa', 'wcag21a', 'wcag21aa', 'wcag22aa', 'best-practice'];

/**
 * Runs axe on the page now, in the light and the dark theme, and fails (softly, so every page of a
 * test is reported) on the violations of the given impacts (all of them when none are given). The
 * full axe answer is attached to the report.
 */
export async function axeCheck(
  page: Page,
  info: TestInfo,
  what: string,
  impacts?: ReadonlySet<string>,
): Promise<void> {
  for (const scheme of ['light', 'dark'] as const) {
    await page.emulateMedia({ colorScheme: scheme });
    const results = await new AxeBuilder({ page }).withTags(TAGS).analyze();
    const bad = impacts ? results.violations.filter((v) => impacts.has(v.impact ?? '')) : results.violations;
    if (bad.length)
      await info.attach(`axe ${what} (${scheme})`, {
        body: JSON.stringify(bad, null, 2),
        contentType: 'application/json',
      });
    expect
      .soft(
        bad.map(
          (v) =>
            `${v.id} [${v.impact}] ${v.help}: ${v.nodes
              .slice(0, 4)
              .map(
                (n) =>
                  `${n.target.join(' ')}${n.failureSummary ? ` — ${n.failureSummary.split('\n')[1]?.trim() ?? ''}` : ''}`,
              )
              .join(' | ')}${v.nodes.length > 4 ? ` (+${v.nodes.length - 4} more)` : ''}`,
        ),
        `${what} (${scheme} theme)`,
      )
      .toEqual([]);
  }
  await page.emulateMedia({ colorScheme: null });
}
