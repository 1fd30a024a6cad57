import AxeBuilder from '@axe-core/playwright';
import { expect, type Page, type TestInfo } from '@playwright/test';

const TAGS = ['wcag2a', 'wcag2aa', 'wcag21a', 'wcag21aa', 'wcag22aa', 'best-practice'];

/**
 * The rules whose answer depends on the colours, and so on the theme: the dark pass runs these. The
 * theme changes colours only (the same DOM, names, roles and sizes), so every other rule would give
 * the light pass's answer again, at the cost of a second full scan (measured: docs/performance.md).
 */
const COLOUR_RULES = ['color-contrast', 'link-in-text-block'];

/**
 * Runs axe on the page now: every rule of TAGS in the light theme, the colour rules again in the
 * dark theme; fails (softly, so every page of a test is reported) on the violations of the given
 * impacts (all of them when none are given). The full axe answer is attached to the report.
 */
export async function axeCheck(
  page: Page,
  info: TestInfo,
  what: string,
  impacts?: ReadonlySet<string>,
): Promise<void> {
  for (const scheme of ['light', 'dark'] as const) {
    await page.emulateMedia({ colorScheme: scheme });
    const builder = new AxeBuilder({ page });
    const results = await (
      scheme === 'light' ? builder.withTags(TAGS) : builder.withRules(COLOUR_RULES)
    ).analyze();
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
