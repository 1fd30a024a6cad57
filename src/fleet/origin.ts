/**
 * Where the console's own origin is. In the browser requests are relative ("" origin); in
 * Node tests they go to a fixed test origin that msw intercepts.
 */
let origin = '';

/**
 * Sent with every request the console makes to its own server. A page of another site cannot set
 * a custom header without a CORS preflight (which the gateway never grants), so the gateway takes
 * it as proof that a request comes from the console itself (see gateway/csrf.ts).
 */
export const CONSOLE_HEADER = 'X-Shopdeck';
export const CONSOLE_HEADERS: Readonly<Record<string, string>> = Object.freeze({ [CONSOLE_HEADER]: '1' });

export function apiOrigin(): string {
  return origin;
}

export function setApiOrigin(o: string): void {
  origin = o.replace(/\/$/, '');
}

export function machineBase(machineId: string): string {
  return `${origin}/machines/${encodeURIComponent(machineId)}`;
}

/** The ws(s):// form of a console URL (relative or absolute http(s)). */
export function wsUrlFor(url: string): string {
  if (/^wss?:\/\//.test(url)) return url;
  if (/^https?:\/\//.test(url)) return url.replace(/^http/, 'ws');
  if (typeof location !== 'undefined' && location.host) {
    return `${location.protocol === 'https:' ? 'wss:' : 'ws:'}//${location.host}${url}`;
  }
  return `ws://localhost${url}`;
}
