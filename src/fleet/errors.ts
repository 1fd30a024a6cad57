import type { ZodError } from 'zod';
import type { LinkProblem } from './types';

/**
 * The error taxonomy of every controller request. A session decides what each means for the
 * link (offline, needs login, protocol error) — the client only classifies.
 */
export type LinkErrorKind = 'network' | 'timeout' | 'http' | 'protocol' | 'vendor' | 'offline' | 'aborted';

export class LinkError extends Error {
  readonly kind: LinkErrorKind;
  /** HTTP status, for `http` (and `vendor` when the vendor sent an HTTP error). */
  readonly status: number | null;
  /** The vendor's own error code ("1003", "101.03", …). */
  readonly vendorCode: string | null;
  /** The vendor's own message, shown as it is. */
  readonly vendorMessage: string | null;
  /** For `protocol`: the path of the value that failed validation ("working" / "heat.heaters.0"). */
  readonly path: string | null;
  /** The console's own server answered (it could not reach the controller, or refused): never the vendor's words. */
  readonly gateway: boolean;

  constructor(
    kind: LinkErrorKind,
    message: string,
    opts: {
      status?: number | null;
      vendorCode?: string | null;
      vendorMessage?: string | null;
      path?: string | null;
      gateway?: boolean;
    } = {},
  ) {
    super(message);
    this.name = 'LinkError';
    this.kind = kind;
    this.status = opts.status ?? null;
    this.vendorCode = opts.vendorCode ?? null;
    this.vendorMessage = opts.vendorMessage ?? null;
    this.path = opts.path ?? null;
    this.gateway = opts.gateway ?? false;
  }

  toProblem(): LinkProblem {
    const p: LinkProblem = { kind: this.kind, message: this.message };
    if (this.path) p.path = this.path;
    return p;
  }
}

export function protocolError(where: string, err: ZodError): LinkError {
  const issue = err.issues[0];
  const path = issue ? issue.path.map(String).join('.') : '';
  const msg = issue ? issue.message : 'invalid payload';
  return new LinkError('protocol', `Unexpected answer from ${where}${path ? ` at "${path}"` : ''}: ${msg}`, {
    path: path || '(root)',
  });
}

export function isLinkError(e: unknown): e is LinkError {
  return e instanceof LinkError;
}

export function describeError(e: unknown): string {
  if (e instanceof LinkError) return e.message;
  if (e instanceof Error) return e.message;
  return String(e);
}
