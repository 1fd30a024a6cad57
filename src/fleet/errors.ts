import type { z } from 'zod/mini';
import type { LinkProblem } from './types';

/**
 * The error taxonomy of every controller request. A session decides what each means for the
 * link (offline, needs login, protocol error) — the client only classifies.
 */
export type LinkErrorKind = 'network' | 'timeout' | 'http' | 'protocol' | 'vendor' | 'offline' | 'aborted';

export interface LinkErrorOptions {
  status?: number | null;
  vendorCode?: string | null;
  vendorMessage?: string | null;
  path?: string | null;
  /** The console's own server made this answer (`X-Shopdeck-Gateway: error`), not the controller. */
  fromGateway?: boolean;
  /** @deprecated the same as `fromGateway`. */
  gateway?: boolean;
  /** A command that may or may not have reached the machine (the gateway's "not confirmed"). */
  notConfirmed?: boolean;
}

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
  /**
   * The console's own server answered (it could not reach the controller, timed out, or refused):
   * its words, never the vendor's; never a model or protocol verdict.
   */
  readonly fromGateway: boolean;
  /** A command that may or may not have reached the machine: report "not confirmed", never retry. */
  readonly notConfirmed: boolean;

  constructor(kind: LinkErrorKind, message: string, opts: LinkErrorOptions = {}) {
    super(message);
    this.name = 'LinkError';
    this.kind = kind;
    this.status = opts.status ?? null;
    this.vendorCode = opts.vendorCode ?? null;
    this.vendorMessage = opts.vendorMessage ?? null;
    this.path = opts.path ?? null;
    this.fromGateway = opts.fromGateway ?? opts.gateway ?? false;
    this.notConfirmed = opts.notConfirmed ?? false;
  }

  /** The same as `fromGateway`. */
  get gateway(): boolean {
    return this.fromGateway;
  }

  /**
   * A link failure, not a verdict on the controller: no whole answer (network, timeout, a cut
   * answer, the gateway could not reach the controller). A model or protocol verdict needs a
   * whole, valid answer from the controller itself.
   */
  get isLinkFailure(): boolean {
    return this.kind === 'network' || this.kind === 'timeout' || this.kind === 'offline';
  }

  toProblem(): LinkProblem {
    const p: LinkProblem = { kind: this.kind, message: this.message };
    if (this.path) p.path = this.path;
    return p;
  }
}

export function protocolError(where: string, err: z.core.$ZodError): LinkError {
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

/**
 * An error in words for the operator: the message, never a stack, never a raw JSON dump (an
 * error whose message is JSON with an `error`/`message` field reads as that field).
 */
export function describeError(e: unknown): string {
  const text = e instanceof Error ? e.message : String(e);
  return wordsOf(text) ?? text;
}

/** The words in a JSON error body (`{"error": "…"}`, `message`, `msg`, `detail`), or null. */
export function wordsOf(text: string): string | null {
  const t = text.trim();
  if (!t.startsWith('{')) return null;
  try {
    const v = JSON.parse(t) as unknown;
    if (typeof v !== 'object' || v === null || Array.isArray(v)) return null;
    const rec = v as Record<string, unknown>;
    for (const k of ['error', 'message', 'msg', 'detail']) {
      const w = rec[k];
      if (typeof w === 'string' && w.trim()) return w.trim();
    }
  } catch {
    return null;
  }
  return null;
}
