import { z } from 'zod/mini';

/**
 * The two pieces of classic zod the page's schemas use that zod/mini has no word for (the page
 * uses zod/mini: src/zod-jitless.ts). Both behave as classic zod's own.
 */

/**
 * Classic `z.preprocess(fn, schema)`: `fn` reshapes the input (any input), then `schema` checks
 * and parses what it returned.
 */
export function preprocess<S extends z.core.$ZodType>(
  fn: (input: unknown) => unknown,
  schema: S,
): z.ZodMiniPipe<z.ZodMiniTransform<unknown, unknown>, S> {
  return z.pipe<z.ZodMiniTransform<unknown, unknown>, S>(z.transform(fn), schema);
}

/** An issue as a transform raises it: its message and where (classic `ctx.addIssue`). */
export interface TransformIssue {
  code: 'custom';
  message: string;
  path?: PropertyKey[];
}

/**
 * Classic `ctx.addIssue(issue)` inside `.transform((value, ctx) => …)`: zod/mini hands a
 * transform the bare parse payload, whose issues take the input the issue is about.
 */
export function addIssue(ctx: z.core.ParsePayload, issue: TransformIssue): void {
  ctx.issues.push({ ...issue, input: ctx.value });
}
