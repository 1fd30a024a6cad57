import js from '@eslint/js';
import tseslint from 'typescript-eslint';
import reactHooks from 'eslint-plugin-react-hooks';
import globals from 'globals';

const families = ['xtool', 'touchcut', 'duet', 'prunt', 'g2core'];

export default tseslint.config(
  {
    ignores: [
      'dist',
      'node_modules',
      'public/mockServiceWorker.js',
      'tests/fixtures',
      'test-results',
      '.shopdeck',
    ],
  },
  js.configs.recommended,
  ...tseslint.configs.recommended,
  {
    languageOptions: { globals: { ...globals.browser, ...globals.node } },
    plugins: { 'react-hooks': reactHooks },
    rules: {
      'react-hooks/rules-of-hooks': 'error',
      'react-hooks/exhaustive-deps': 'warn',
      '@typescript-eslint/no-explicit-any': 'error',
      '@typescript-eslint/no-unused-vars': ['error', { argsIgnorePattern: '^_', varsIgnorePattern: '^_' }],
    },
  },
  // Playwright fixtures are destructured objects; `({}, testInfo)` is its documented idiom.
  { files: ['tests/e2e/**'], rules: { 'no-empty-pattern': 'off' } },
  // Imports run one way: app -> controllers -> fleet -> forms, ui.
  {
    files: ['src/fleet/**', 'src/forms/**', 'src/ui/**'],
    rules: {
      'no-restricted-imports': [
        'error',
        {
          patterns: [
            {
              group: ['**/controllers/**', '**/app/**'],
              message: 'fleet/, forms/ and ui/ never import controllers/ or app/',
            },
          ],
        },
      ],
    },
  },
  ...families.map((f) => ({
    files: [`src/controllers/${f}/**`],
    rules: {
      'no-restricted-imports': [
        'error',
        {
          patterns: [
            {
              group: [
                ...families.filter((o) => o !== f).flatMap((o) => [`**/${o}`, `**/${o}/**`]),
                '**/app/**',
              ],
              message: 'a controller family never imports another family or app/',
            },
          ],
        },
      ],
    },
  })),
);
