/**
 * Where the console's own origin is. In the browser requests are relative ("" origin); in
 * Node tests they go to a fixed test origin that msw intercepts.
 */
let origin = '';

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
