import { fileURLToPath } from 'node:url';
import { ESLint } from 'eslint';
import { describe, expect, it } from 'vitest';

/**
 * Issue 12 (7): the import-boundary lint works on resolved paths, so a folder index
 * (`'../controllers'`, `'..'`) is no way around it. Each case lints a line of source under the
 * name of a real file of the layer, with eslint.config.js's boundary rules alone: neither needs
 * type information, so no TypeScript program is built (that took minutes on 2 cores).
 */
const root = fileURLToPath(new URL('../..', import.meta.url));

const BOUNDARY_RULES = new Set(['import-x/no-restricted-paths', 'no-restricted-imports']);
const eslint = new ESLint({
  cwd: root,
  ruleFilter: ({ ruleId }) => BOUNDARY_RULES.has(ruleId),
  overrideConfig: { languageOptions: { parserOptions: { projectService: false } } },
});

async function boundaryErrors(filePath: string, code: string): Promise<string[]> {
  const [result] = await eslint.lintText(code, { filePath });
  return (result?.messages ?? [])
    .filter((m) => m.severity === 2 && m.ruleId !== null && BOUNDARY_RULES.has(m.ruleId))
    .map((m) => m.message);
}

describe('import boundaries (eslint.config.js)', { timeout: 120_000 }, () => {
  it("catches fleet/ importing controllers/ through the folder index '../controllers'", async () => {
    const errors = await boundaryErrors(
      'src/fleet/errors.ts',
      "import { controllers } from '../controllers';\nexport const n = Object.keys(controllers).length;\n",
    );
    expect(errors).toHaveLength(1);
  });

  it("catches a family importing the registry of every family through '..'", async () => {
    const errors = await boundaryErrors(
      'src/controllers/duet/wire.ts',
      "import { controllers } from '..';\nexport const n = Object.keys(controllers).length;\n",
    );
    expect(errors).toHaveLength(1);
  });

  it("catches ui/ reaching app/ through a path that names no 'app' folder pattern", async () => {
    const errors = await boundaryErrors(
      'src/ui/safe-url.ts',
      "import { navigate } from '../../src/app/router';\nexport const go = navigate;\n",
    );
    expect(errors).toHaveLength(1);
  });

  it('still catches the plain cases, and lets the allowed direction through', async () => {
    expect(
      await boundaryErrors(
        'src/controllers/duet/wire.ts',
        "import { g2coreModule } from '../g2core/module';\nexport const m = g2coreModule;\n",
      ),
    ).toHaveLength(1);
    expect(
      await boundaryErrors(
        'src/controllers/duet/wire.ts',
        "import { formatBytes } from '../../ui';\nimport { LinkError } from '../../fleet/errors';\nexport const x = [formatBytes, LinkError];\n",
      ),
    ).toEqual([]);
    expect(
      await boundaryErrors(
        'src/app/boot.ts',
        "import { controllers } from '../controllers';\nexport const c = controllers;\n",
      ),
    ).toEqual([]);
  });
});
