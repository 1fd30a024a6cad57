/**
 * What `import … from 'zod/mini'` means in the browser build (vite.config.ts `resolve.alias`) and
 * in the unit tests (vitest.config.ts, so they parse as the page does): zod/mini, configured before
 * anything can build a schema. Every module that imports zod/mini runs after this one, whatever
 * chunk the bundler puts it in; a side-effect import first in main.tsx did not hold: the shared
 * chunks an entry imports run before the entry's own code.
 *
 * - zod/mini, not classic zod: the page's schemas use its functional API
 *   (`z.optional(z.string())`), which the bundler tree-shakes to what they use (~10 KiB gzip
 *   instead of classic zod's 25.5, whose methods bring every schema kind, JSON Schema included).
 *   Only `zod/mini` is aliased: classic `zod` is for the gateway's own schemas (Node), and
 *   eslint keeps it out of `src/`.
 * - English messages (`en`): zod/mini has no locale of its own, every issue would read
 *   "Invalid input"; the console shows issues as `path: message`, worded as classic zod words
 *   them. (The gateway runs some of these schemas without this module: classic zod registers
 *   the same English locale there when the first of the gateway's own schemas is built, at import.)
 * - `jitless`: zod 4 compiles classic object parsers with `new Function`, and the console's
 *   Content-Security-Policy forbids eval (gateway/page-headers.ts). zod/mini's objects never
 *   compile, but the flag stays set so nothing in the page can ever try (a CSP violation each).
 *
 * Not installed: classic zod's default memoizer (cycle support for recursive schemas on cyclic
 * input): the page's one recursive schema (prunt's config nodes, prunt/wire.ts) parses JSON, which
 * has no cycles, and only after its depth is checked.
 */
import { en } from 'zod/v4/locales';
import { config } from 'zod/v4/mini';

config({ jitless: true });
config(en());

export * from 'zod/v4/mini';
