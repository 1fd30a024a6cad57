import { jsonResponse } from '../../../fleet/sim';
import { httpStatusFor, statusText } from '../codes';

/**
 * How the simulated g2core fails: a status code (codes.ts) thrown as G2Fail anywhere in the
 * simulator and answered by the routes as the design's error body, plus the request-body and
 * filter parsing that can fail with one.
 */

export class G2Fail extends Error {
  constructor(
    readonly code: number,
    readonly additional = '',
  ) {
    super(statusText(code));
  }
}

export function errorResponse(code: number, additional = ''): Response {
  return jsonResponse(
    { status: { code, description: statusText(code), additional_description: additional } },
    httpStatusFor(code),
  );
}

export function isRecord(v: unknown): v is Record<string, unknown> {
  return typeof v === 'object' && v !== null && !Array.isArray(v);
}

/** The request's JSON body: 101 when there is none, 111 when it does not parse. */
export async function readBody(req: Request): Promise<unknown> {
  const text = await req.text();
  if (text.trim() === '') throw new G2Fail(101, 'a JSON body is required');
  try {
    return JSON.parse(text) as unknown;
  } catch {
    throw new G2Fail(111, text.slice(0, 60));
  }
}

/** The `filter` query parameter as a JSON object, or null without one. */
export function parseFilter(query: URLSearchParams): Record<string, unknown> | null {
  const f = query.get('filter');
  if (f === null) return null;
  let spec: unknown;
  try {
    spec = JSON.parse(f);
  } catch {
    throw new G2Fail(111, `filter: ${f.slice(0, 60)}`);
  }
  if (!isRecord(spec)) throw new G2Fail(101, 'filter must be a JSON object');
  return spec;
}
