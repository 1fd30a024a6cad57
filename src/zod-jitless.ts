/**
 * What `import … from 'zod'` means in the browser build (vite.config.ts `resolve.alias`): zod with
 * `jitless` set before anything can build a schema. zod 4 compiles object parsers with
 * `new Function` (it tries as soon as an object schema is made), and the console's
 * Content-Security-Policy forbids eval (gateway/page-headers.ts): without this every page reports
 * CSP violations, and zod falls back anyway. Every module that imports zod runs after this one,
 * whatever chunk the bundler puts it in; a side-effect import first in main.tsx did not hold: the
 * shared chunks an entry imports run before the entry's own code.
 */
import { z } from 'zod/v4';

z.config({ jitless: true });

export * from 'zod/v4';
export { z as default };
