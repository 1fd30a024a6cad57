import { z } from 'zod/mini';
import { LinkError } from '../../fleet/errors';

/**
 * What the page needs before it knows whether a Duet is standalone (`client.ts` `connect`): the
 * connect answer and its reading. The rest of the standalone API (`rrf-client.ts`) is loaded only
 * for a standalone board.
 */

export const connectAnswer = z.looseObject({
  err: z.optional(z.number()),
  isEmulated: z.optional(z.boolean()),
  sessionKey: z.nullish(z.union([z.string(), z.number()])),
});
export type ConnectAnswer = z.infer<typeof connectAnswer>;

/** A connect answer of a standalone board (numeric `err`, not DSF's emulation). */
export function isStandaloneAnswer(a: ConnectAnswer): boolean {
  return typeof a.err === 'number' && a.isEmulated !== true;
}

/** RRF's `err` 1 of `rr_connect`, or 2 (no free session: RRF has 8), as the console's errors. */
export function connectRefusal(err: number): LinkError | null {
  if (err === 0) return null;
  if (err === 1)
    return new LinkError('http', 'HTTP 403: the Duet refused the password (rr_connect err 1)', {
      status: 403,
    });
  return new LinkError(
    'vendor',
    `The Duet has no free session (rr_connect err ${err}: too many clients are connected to it; retried)`,
    { vendorCode: String(err) },
  );
}

/** `?a=1&b=x%20y`: values encoded with encodeURIComponent (a space is %20, never +). */
export function rrQuery(params: Record<string, string | number | undefined>): string {
  const parts: string[] = [];
  for (const [k, v] of Object.entries(params))
    if (v !== undefined) parts.push(`${k}=${encodeURIComponent(String(v))}`);
  return parts.length ? `?${parts.join('&')}` : '';
}
