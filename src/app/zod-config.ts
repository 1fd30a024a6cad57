import { z } from 'zod';

/**
 * Imported first by main.tsx, before any schema exists: zod 4 compiles object parsers with
 * `new Function` unless told not to, and the console's Content-Security-Policy forbids eval
 * (gateway/page-headers.ts). Without this, every page load reports CSP violations and zod falls
 * back anyway.
 */
z.config({ jitless: true });
