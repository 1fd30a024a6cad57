import type { Role } from './types';

/**
 * Access declarations: each controller family says, next to its client, which controller
 * requests belong to which role. The gateway enforces it on every proxied request (HTTP and
 * WebSocket); the UI uses the same declaration to hide or disable what a user may not do.
 */

export interface AccessRequest {
  method: string;
  /** Controller path without the `/machines/<id>` prefix, e.g. "/cnc/data". */
  path: string;
  query: URLSearchParams;
  /** Request body as text, for families that classify by content (Duet `POST /machine/code`). */
  body?: string;
  /** The body's Content-Type, when the body is given (a multipart upload needs its boundary). */
  contentType?: string;
  /** True for a WebSocket upgrade. */
  websocket?: boolean;
}

export interface AccessDecision {
  /** Least role that may send this request. */
  role: Role;
  /** A command: written to the audit log even when it is a GET. */
  command: boolean;
  /** What it does, in words, for refusals and the audit log ("stop the job"). */
  label: string;
  /**
   * Which console command this request is, as the family classifies it ("xtool.pause"): the
   * audit's `commandId`, by which the job history names who started, paused, resumed and stopped
   * a job. Derived from the request itself, never from what the page says it sent.
   */
  id?: string;
}

export type AccessPolicy = (req: AccessRequest) => AccessDecision;

/** Helpers for declaring policies. */
export const read = (label = 'read status'): AccessDecision => ({ role: 'viewer', command: false, label });
export const operator = (label: string, id?: string): AccessDecision => ({
  role: 'operator',
  command: true,
  label,
  ...(id ? { id } : {}),
});
export const supervisor = (label: string): AccessDecision => ({ role: 'supervisor', command: true, label });

/**
 * Default for requests a family did not declare: GET is a read, anything else a
 * supervisor-only command. Unknown is never "allowed to everyone".
 */
export function defaultDecision(req: AccessRequest): AccessDecision {
  if (req.websocket) return read('live updates');
  return req.method === 'GET' || req.method === 'HEAD'
    ? read()
    : supervisor(`${req.method} ${req.path} (not declared by the family: supervisor only)`);
}

/**
 * Whether the gateway must buffer the request body to classify it. A role says the least role any
 * such body can need (the gateway refuses anyone below it before reading the body); `true` means
 * operator: a body-classified request is a command.
 */
export type BodyNeeded = (method: string, path: string) => boolean | Role;
