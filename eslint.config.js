import js from '@eslint/js';
import tseslint from 'typescript-eslint';
import reactHooks from 'eslint-plugin-react-hooks';
import { createNodeResolver, importX } from 'eslint-plugin-import-x';
import jsxA11y from 'eslint-plugin-jsx-a11y';
import globals from 'globals';
import { readdirSync } from 'node:fs';

// The controller families: the folders of src/controllers (a family is its folder).
const families = readdirSync(new URL('./src/controllers/', import.meta.url), { withFileTypes: true })
  .filter((d) => d.isDirectory())
  .map((d) => d.name);

// Import boundaries are checked on the path an import RESOLVES to, so a folder index
// ('../controllers', '..') or any other spelling of a path is no way around them.
const controllers = './src/controllers';
const boundaryZones = [
  // Imports run one way: app -> controllers -> fleet -> forms, ui.
  {
    target: ['./src/fleet', './src/forms', './src/ui'],
    from: ['./src/controllers', './src/app'],
    message: 'fleet/, forms/ and ui/ never import controllers/ or app/',
  },
  {
    target: ['./src/forms', './src/ui'],
    from: './src/fleet',
    message: 'forms/ and ui/ never import fleet/',
  },
  ...families.map((f) => ({
    target: `${controllers}/${f}`,
    from: [
      ...families.filter((o) => o !== f).map((o) => `${controllers}/${o}`),
      // The registries import every family.
      `${controllers}/index.ts`,
      `${controllers}/families.ts`,
      './src/app',
    ],
    message: 'a controller family never imports another family, the registries or app/',
  })),
  // A family's server part (`<kind>/server/`) is Node-only: the gateway and the Node list of
  // families (families.ts) load it, nothing of the page does (gateway/bundle.test.ts).
  {
    target: [
      './src/app',
      './src/fleet',
      './src/forms',
      './src/ui',
      `${controllers}/!(families).{ts,tsx}`,
      `${controllers}/*/*.{ts,tsx}`,
      `${controllers}/*/!(server)/**`,
    ],
    from: `${controllers}/*/server/**`,
    message: "a family's server/ part is Node-only: only families.ts and the gateway import it",
  },
];

export default tseslint.config(
  {
    ignores: ['dist', 'node_modules', 'tests/fixtures', 'test-results', '.shopdeck'],
  },
  js.configs.recommended,
  ...tseslint.configs.recommended,
  {
    languageOptions: { globals: { ...globals.browser, ...globals.node } },
    plugins: { 'react-hooks': reactHooks, 'import-x': importX },
    settings: {
      'import-x/resolver-next': [
        createNodeResolver({ extensions: ['.ts', '.tsx', '.mts', '.js', '.mjs', '.jsx', '.json'] }),
      ],
    },
    rules: {
      'react-hooks/rules-of-hooks': 'error',
      'react-hooks/exhaustive-deps': 'warn',
      '@typescript-eslint/no-explicit-any': 'error',
      '@typescript-eslint/no-unused-vars': ['error', { argsIgnorePattern: '^_', varsIgnorePattern: '^_' }],
      'import-x/no-restricted-paths': ['error', { basePath: import.meta.dirname, zones: boundaryZones }],
      'import-x/no-cycle': ['error', { ignoreExternal: true }],
    },
  },
  // Type-aware rules: the TypeScript sources the tsconfig holds (src, gateway, tests, scripts).
  {
    files: ['**/*.{ts,tsx,mts}'],
    languageOptions: {
      parserOptions: { projectService: true, tsconfigRootDir: import.meta.dirname },
    },
    rules: {
      '@typescript-eslint/no-floating-promises': 'error',
      '@typescript-eslint/switch-exhaustiveness-check': [
        'error',
        { considerDefaultExhaustiveForUnions: true },
      ],
    },
  },
  // The page's zod is zod/mini (src/zod-jitless.ts): classic zod, whose methods bring every schema
  // kind (~25 KiB gzip), stays out of src/. The gateway's own schemas (Node) may use it, and so
  // may a family's server part (`<kind>/server/`, Node-only, never in the page).
  {
    files: ['src/**/*.{ts,tsx}'],
    ignores: ['src/controllers/*/server/**'],
    rules: {
      'no-restricted-imports': [
        'error',
        ...['zod', 'zod/v4', 'zod/v3'].map((name) => ({
          name,
          message: "The page uses zod/mini: import { z } from 'zod/mini' (src/zod-jitless.ts).",
        })),
      ],
    },
  },
  { files: ['**/*.tsx'], ...jsxA11y.flatConfigs.recommended },
  // Playwright fixtures are destructured objects; `({}, testInfo)` is its documented idiom.
  { files: ['tests/e2e/**'], rules: { 'no-empty-pattern': 'off' } },
);
